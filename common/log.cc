#include "common/log.h"

#include <array>
#include <memory>
#include <mutex>
#include <utility>

#include <CLI/CLI.hpp>
#include <spdlog/sinks/stdout_color_sinks.h>

namespace holo {
namespace {

constexpr std::array<std::pair<std::string_view, spdlog::level::level_enum>, 6> kLevels = {{
    {"trace", spdlog::level::trace},
    {"debug", spdlog::level::debug},
    {"info", spdlog::level::info},
    {"warn", spdlog::level::warn},
    {"error", spdlog::level::err},
    {"off", spdlog::level::off},
}};

}  // namespace

std::optional<spdlog::level::level_enum> ParseLogLevel(std::string_view name) {
  for (const auto& [n, level] : kLevels)
    if (n == name) return level;
  return std::nullopt;
}

void InitLogging(spdlog::level::level_enum level) {
  static std::once_flag once;
  std::call_once(once, [] {
    // spdlog's own default logger writes to stdout, where the JSON lines go.
    auto logger = std::make_shared<spdlog::logger>("", std::make_shared<spdlog::sinks::stderr_color_sink_mt>());
    // The sink writes and flushes each line whole, under its mutex: lines of
    // concurrent threads never interleave.
    logger->set_pattern("[%H:%M:%S.%e] [%^%l%$] %v");
    spdlog::set_default_logger(std::move(logger));
  });
  spdlog::set_level(level);
}

void AddLogLevelOption(CLI::App& app) {
  InitLogging(spdlog::level::info);
  app.add_option_function<std::string>(
         "--log-level",
         [](const std::string& name) {
           // The check below has already refused anything else.
           if (auto level = ParseLogLevel(name)) InitLogging(*level);
         },
         "log lines on stderr from this level up: " + std::string(kLogLevelNames) + " (default info)")
      ->check([](const std::string& name) {
        return ParseLogLevel(name) ? std::string() : "expected " + std::string(kLogLevelNames) + ", got '" + name + "'";
      });
}

}  // namespace holo
