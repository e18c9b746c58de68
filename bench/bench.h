// Benchmark registry and JSON-line output for holoport-bench.
#pragma once

#include <functional>
#include <map>
#include <string>
#include <vector>

namespace CLI {
class App;
}  // namespace CLI

namespace holo::bench {

struct BenchArgs {
  std::string workload = "S8-QVGA";
  bool json = false;       // JSON lines only (no human-readable text)
  int frames = 0;          // 0 = the benchmark's default
  int repeats = 3;         // runs to take the median of
};

// Returns a process exit code (0 = success).
using BenchFn = std::function<int(const BenchArgs&)>;

// A benchmark's own options, through CLI11: its setup function declares them
// on `app` (bound to state the function owns, e.g. a shared_ptr to an options
// struct) and returns the function that runs the benchmark once
// holoport-bench has parsed the command line. holoport-bench adds the common
// options (--workload, --json, --frames, --repeats, --log-level) and --help,
// prints the benchmark's help for `holoport-bench NAME --help`, and refuses
// any option the benchmark did not declare (an error naming it, exit 2).
using BenchSetup = std::function<BenchFn(CLI::App& app)>;

struct BenchInfo {
  std::string description;
  BenchSetup setup;  // declares the benchmark's options
};

std::map<std::string, BenchInfo>& Registry();
// A benchmark with no options besides the common ones.
bool Register(const std::string& name, const std::string& description, BenchFn fn);
bool RegisterWithOptions(const std::string& name, const std::string& description, BenchSetup setup);
// Setup of a benchmark with no options besides the common ones.
BenchSetup NoOptions(BenchFn fn);
// For a benchmark's setup: takes common options it does not read (of
// "--workload", "--frames", "--repeats") off `app`, so that they are refused
// like any unknown option (exit 2, the option named) instead of accepted and
// silently ignored.
void DropCommonOptions(CLI::App& app, const std::vector<std::string>& names);

// Prints one figure as a JSON line:
// {"bench":"studio","workload":"S8-QVGA","metric":"fps","value":31.4,"unit":"1/s", ...qualifiers}
void EmitFigure(const std::string& bench, const std::string& workload, const std::string& metric, double value,
                const std::string& unit, const std::map<std::string, std::string>& qualifiers = {});

double Median(std::vector<double> values);
// `v` with `digits` digits after the point ("%.*f"), for qualifiers.
std::string Fixed(double v, int digits);
// CPU time of the whole process so far (all threads), ms: steadier than wall
// time on a shared machine.
double ProcessCpuMs();
// Arithmetic mean; 0 for an empty list.
double Mean(const std::vector<double>& values);

}  // namespace holo::bench

// HOLO_REGISTER_BENCH: a benchmark with only the common options;
// HOLO_REGISTER_BENCH_OPTIONS: one that declares its own (BenchSetup).
#define HOLO_REGISTER_BENCH(name, description, fn) \
  static const bool holo_bench_registered_##fn = ::holo::bench::Register(name, description, fn)
#define HOLO_BENCH_CONCAT_(a, b) a##b
#define HOLO_BENCH_CONCAT(a, b) HOLO_BENCH_CONCAT_(a, b)
#define HOLO_REGISTER_BENCH_OPTIONS(name, description, setup)                     \
  static const bool HOLO_BENCH_CONCAT(holo_bench_registered_, __LINE__) = \
      ::holo::bench::RegisterWithOptions(name, description, setup)
