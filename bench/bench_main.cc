// holoport-bench BENCHMARK [--workload S8-QVGA|S8-VGA] [--json] [--frames N] [--repeats N] [--log-level L] [its
// options] holoport-bench BENCHMARK --help lists the benchmark's own options.
#include <cstdio>
#include <string>

#include <CLI/CLI.hpp>

#include "bench.h"
#include "common/log.h"
#include "common/status.h"

namespace {

void PrintHelp() {
  std::printf(
      "usage: holoport-bench BENCHMARK [--workload NAME] [--json] [--frames N] [--repeats N] [--log-level L] "
      "[options]\n"
      "       holoport-bench BENCHMARK --help   (the benchmark's own options)\n\n"
      "Runs one benchmark and prints its figures, one JSON object per line\n"
      "({\"bench\":...,\"workload\":...,\"metric\":...,\"value\":...,\"unit\":...}).\n\n"
      "options:\n"
      "  --workload NAME  standard workload: S8-QVGA (default) or S8-VGA\n"
      "  --json           print only the JSON lines (no progress text on stderr)\n"
      "  --frames N       frames per run (default: the benchmark's own)\n"
      "  --repeats N      runs; figures are medians (default 3)\n"
      "  --log-level L    log lines on stderr from this level up: %s (default info)\n"
      "A benchmark that does not read --workload, --frames or --repeats refuses it.\n\n"
      "benchmarks:\n",
      holo::kLogLevelNames);
  for (const auto& [name, info] : holo::bench::Registry()) std::printf("  %-14s %s\n", name.c_str(), info.description.c_str());
}

// CLI11 parses the common options and the benchmark's own, and refuses what
// nobody declared.
int Run(const std::string& name, const holo::bench::BenchInfo& info, int argc, char** argv) {
  holo::bench::BenchArgs args;
  CLI::App app(info.description, "holoport-bench " + name);
  app.add_option("--workload", args.workload, "standard workload: S8-QVGA or S8-VGA")->capture_default_str();
  app.add_flag("--json", args.json, "print only the JSON lines (no progress text on stderr)");
  app.add_option("--frames", args.frames, "frames per run (default: the benchmark's own)")
      ->check(CLI::Range(1, 1000000));
  app.add_option("--repeats", args.repeats, "runs; figures are medians")->check(CLI::Range(1, 1000000))->capture_default_str();
  holo::AddLogLevelOption(app);
  holo::bench::BenchFn fn = info.setup(app);
  try {
    // argv[1] (the benchmark's name) stands in for the program name.
    app.parse(argc - 1, argv + 1);
  } catch (const CLI::CallForHelp& e) {
    return app.exit(e);
  } catch (const CLI::ParseError& e) {
    // The command line's answer (like CLI11's own in the other programs), not a log line.
    std::fprintf(stderr, "holoport-bench %s: %s (see holoport-bench %s --help)\n", name.c_str(), e.what(), name.c_str());
    return 2;
  }
  return fn(args);
}

}  // namespace

namespace holo::bench {

void DropCommonOptions(CLI::App& app, const std::vector<std::string>& names) {
  for (const std::string& name : names) {
    CLI::Option* option = app.get_option_no_throw(name);
    HOLO_CHECK_MSG(option != nullptr, "no common option " + name);
    app.remove_option(option);
  }
}

}  // namespace holo::bench

int main(int argc, char** argv) {
  holo::InitLogging();
  if (argc < 2 || std::string(argv[1]) == "--help" || std::string(argv[1]) == "-h") {
    PrintHelp();
    return argc < 2 ? 2 : 0;
  }
  if (std::string(argv[1]) == "--list") {  // the benchmarks' names, one a line (for tests)
    for (const auto& [name, info] : holo::bench::Registry()) std::printf("%s\n", name.c_str());
    return 0;
  }
  const std::string name = argv[1];
  auto it = holo::bench::Registry().find(name);
  if (it == holo::bench::Registry().end()) {
    std::fprintf(stderr, "holoport-bench: unknown benchmark '%s' (try --help)\n", name.c_str());
    return 2;
  }
  return Run(name, it->second, argc, argv);
}
