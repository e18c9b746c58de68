// Benchmark registry and JSON-line output for holoport-bench.
#pragma once

#include <functional>
#include <map>
#include <string>
#include <vector>

namespace holo::bench {

struct BenchArgs {
  std::string workload = "S8-QVGA";
  bool json = false;       // JSON lines only (no human-readable text)
  int frames = 0;          // 0 = the benchmark's default
  int repeats = 3;         // runs to take the median of
  std::vector<std::string> extra;  // unparsed options for the benchmark
};

// Returns a process exit code (0 = success).
using BenchFn = std::function<int(const BenchArgs&)>;

struct BenchInfo {
  std::string description;
  BenchFn fn;
};

std::map<std::string, BenchInfo>& Registry();
bool Register(const std::string& name, const std::string& description, BenchFn fn);

// Prints one figure as a JSON line:
// {"bench":"studio","workload":"S8-QVGA","metric":"fps","value":31.4,"unit":"1/s", ...qualifiers}
void EmitFigure(const std::string& bench, const std::string& workload, const std::string& metric, double value,
                const std::string& unit, const std::map<std::string, std::string>& qualifiers = {});

double Median(std::vector<double> values);
// CPU time of the whole process so far (all threads), ms: steadier than wall
// time on a shared machine.
double ProcessCpuMs();
// Arithmetic mean; 0 for an empty list.
double Mean(const std::vector<double>& values);

}  // namespace holo::bench

#define HOLO_REGISTER_BENCH(name, description, fn) \
  static const bool holo_bench_registered_##fn = ::holo::bench::Register(name, description, fn)
