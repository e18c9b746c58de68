// Logging: every program and library writes its progress, warnings and errors
// through spdlog's default logger, which InitLogging points at stderr with one
// line format and a level. stdout stays for machine-readable output (JSON
// lines), which never goes through the logger.
//
// Levels as used here:
//   error  the program or a component cannot go on ("cannot open rig.yaml: ...")
//   warn   something outside went wrong and was handled (a refused viewer, a
//          skipped bad message, a fallback taken)
//   info   what the program is doing: start-up, connections, periodic
//          progress and the end summary (the default level)
//   debug  per-frame and per-message detail
//   trace  finer still
//
// Library code logs with spdlog::info(...) etc. (fmt-style "{}" formats) and
// needs nothing else; a program calls AddLogLevelOption (or InitLogging) once.
#pragma once

#include <optional>
#include <string>
#include <string_view>

#include <spdlog/spdlog.h>

namespace CLI {
class App;
}  // namespace CLI

namespace holo {

// Level names accepted by --log-level, in order: "trace|debug|info|warn|error|off".
inline constexpr const char* kLogLevelNames = "trace|debug|info|warn|error|off";

// The level named `name` (one of kLogLevelNames), or nullopt.
std::optional<spdlog::level::level_enum> ParseLogLevel(std::string_view name);

// Makes the default logger write to stderr as "[HH:MM:SS.mmm] [level] message"
// (the level coloured on a terminal) and sets its level. Safe to call again
// (later calls only change the level). Threads may log concurrently.
void InitLogging(spdlog::level::level_enum level = spdlog::level::info);

// InitLogging(info) now, and adds `--log-level LEVEL` to `app`; once parsed,
// the logger takes that level. A name outside kLogLevelNames is refused by
// the parse (CLI11 error naming the option).
void AddLogLevelOption(CLI::App& app);

}  // namespace holo
