// holoport-bench SUBCOMMAND [--workload S8-QVGA|S8-VGA] [--json] [--frames N] [--repeats N]
#include <cstdio>
#include <cstdlib>
#include <string>

#include "bench.h"

namespace {

void PrintHelp() {
  std::printf(
      "usage: holoport-bench BENCHMARK [--workload NAME] [--json] [--frames N] [--repeats N]\n\n"
      "Runs one benchmark and prints its figures, one JSON object per line\n"
      "({\"bench\":...,\"workload\":...,\"metric\":...,\"value\":...,\"unit\":...}).\n\n"
      "options:\n"
      "  --workload NAME  standard workload: S8-QVGA (default) or S8-VGA\n"
      "  --json           print only the JSON lines (no progress text on stderr)\n"
      "  --frames N       frames per run (default: the benchmark's own)\n"
      "  --repeats N      runs; figures are medians (default 3)\n\n"
      "benchmarks:\n");
  for (const auto& [name, info] : holo::bench::Registry()) std::printf("  %-12s %s\n", name.c_str(), info.description.c_str());
}

bool ParseInt(const char* s, int* out) {
  char* end = nullptr;
  const long v = std::strtol(s, &end, 10);
  if (end == s || *end != '\0' || v < 1 || v > 1000000) return false;
  *out = static_cast<int>(v);
  return true;
}

}  // namespace

int main(int argc, char** argv) {
  if (argc < 2 || std::string(argv[1]) == "--help" || std::string(argv[1]) == "-h") {
    PrintHelp();
    return argc < 2 ? 2 : 0;
  }
  const std::string name = argv[1];
  auto it = holo::bench::Registry().find(name);
  if (it == holo::bench::Registry().end()) {
    std::fprintf(stderr, "holoport-bench: unknown benchmark '%s' (try --help)\n", name.c_str());
    return 2;
  }
  holo::bench::BenchArgs args;
  for (int i = 2; i < argc; ++i) {
    const std::string a = argv[i];
    auto need = [&](const char* what) -> const char* {
      if (i + 1 >= argc) {
        std::fprintf(stderr, "holoport-bench: %s needs a value\n", what);
        std::exit(2);
      }
      return argv[++i];
    };
    if (a == "--help" || a == "-h") {
      PrintHelp();
      return 0;
    } else if (a == "--workload") {
      args.workload = need("--workload");
    } else if (a == "--json") {
      args.json = true;
    } else if (a == "--frames") {
      if (!ParseInt(need("--frames"), &args.frames)) {
        std::fprintf(stderr, "holoport-bench: --frames must be a positive integer\n");
        return 2;
      }
    } else if (a == "--repeats") {
      if (!ParseInt(need("--repeats"), &args.repeats)) {
        std::fprintf(stderr, "holoport-bench: --repeats must be a positive integer\n");
        return 2;
      }
    } else {
      args.extra.push_back(a);
    }
  }
  return it->second.fn(args);
}
