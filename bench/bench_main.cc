// holoport-bench BENCHMARK [--workload S8-QVGA|S8-VGA] [--json] [--frames N] [--repeats N] [its options]
// holoport-bench BENCHMARK --help lists the benchmark's own options.
#include <cstdio>
#include <cstdlib>
#include <string>

#include <CLI/CLI.hpp>

#include "bench.h"

namespace {

constexpr const char* kCommonHelp =
    "  --workload NAME  standard workload: S8-QVGA (default) or S8-VGA\n"
    "  --json           print only the JSON lines (no progress text on stderr)\n"
    "  --frames N       frames per run (default: the benchmark's own)\n"
    "  --repeats N      runs; figures are medians (default 3)\n";

void PrintHelp() {
  std::printf(
      "usage: holoport-bench BENCHMARK [--workload NAME] [--json] [--frames N] [--repeats N] [options]\n"
      "       holoport-bench BENCHMARK --help   (the benchmark's own options)\n\n"
      "Runs one benchmark and prints its figures, one JSON object per line\n"
      "({\"bench\":...,\"workload\":...,\"metric\":...,\"value\":...,\"unit\":...}).\n\n"
      "options:\n%s\nbenchmarks:\n",
      kCommonHelp);
  for (const auto& [name, info] : holo::bench::Registry()) std::printf("  %-14s %s\n", name.c_str(), info.description.c_str());
}

bool ParseInt(const char* s, int* out) {
  char* end = nullptr;
  const long v = std::strtol(s, &end, 10);
  if (end == s || *end != '\0' || v < 1 || v > 1000000) return false;
  *out = static_cast<int>(v);
  return true;
}

// A benchmark that declares its options: CLI11 parses everything and refuses
// what nobody declared.
int RunDeclared(const std::string& name, const holo::bench::BenchInfo& info, int argc, char** argv) {
  holo::bench::BenchArgs args;
  CLI::App app(info.description, "holoport-bench " + name);
  app.add_option("--workload", args.workload, "standard workload: S8-QVGA or S8-VGA")->capture_default_str();
  app.add_flag("--json", args.json, "print only the JSON lines (no progress text on stderr)");
  app.add_option("--frames", args.frames, "frames per run (default: the benchmark's own)")
      ->check(CLI::Range(1, 1000000));
  app.add_option("--repeats", args.repeats, "runs; figures are medians")->check(CLI::Range(1, 1000000))->capture_default_str();
  holo::bench::BenchFn fn = info.setup(app);
  try {
    // argv[1] (the benchmark's name) stands in for the program name.
    app.parse(argc - 1, argv + 1);
  } catch (const CLI::CallForHelp& e) {
    return app.exit(e);
  } catch (const CLI::ParseError& e) {
    std::fprintf(stderr, "holoport-bench %s: %s (see holoport-bench %s --help)\n", name.c_str(), e.what(), name.c_str());
    return 2;
  }
  return fn(args);
}

// A benchmark that parses its own options from args.extra.
int RunOwnParser(const std::string& name, const holo::bench::BenchInfo& info, int argc, char** argv) {
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
      std::printf("%s\nusage: holoport-bench %s [options]\n\noptions:\n%s"
                  "  (its further options are read by the benchmark itself: see bench/ and docs/)\n",
                  info.description.c_str(), name.c_str(), kCommonHelp);
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
  return info.fn(args);
}

}  // namespace

int main(int argc, char** argv) {
  if (argc < 2 || std::string(argv[1]) == "--help" || std::string(argv[1]) == "-h") {
    PrintHelp();
    return argc < 2 ? 2 : 0;
  }
  if (std::string(argv[1]) == "--list") {  // NAME and whether it declares its options (for tests)
    for (const auto& [name, info] : holo::bench::Registry())
      std::printf("%s %s\n", name.c_str(), info.setup ? "declared" : "own-parser");
    return 0;
  }
  const std::string name = argv[1];
  auto it = holo::bench::Registry().find(name);
  if (it == holo::bench::Registry().end()) {
    std::fprintf(stderr, "holoport-bench: unknown benchmark '%s' (try --help)\n", name.c_str());
    return 2;
  }
  return it->second.setup ? RunDeclared(name, it->second, argc, argv) : RunOwnParser(name, it->second, argc, argv);
}
