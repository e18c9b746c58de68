// common/log.h: --log-level parsing, the level taking effect, lines on
// stderr (never stdout, where programs print their JSON lines).
#include <string>
#include <vector>

#include <CLI/CLI.hpp>
#include <gtest/gtest.h>

#include "common/log.h"

namespace holo {
namespace {

TEST(Log, ParseLogLevelNames) {
  EXPECT_EQ(ParseLogLevel("trace"), spdlog::level::trace);
  EXPECT_EQ(ParseLogLevel("debug"), spdlog::level::debug);
  EXPECT_EQ(ParseLogLevel("info"), spdlog::level::info);
  EXPECT_EQ(ParseLogLevel("warn"), spdlog::level::warn);
  EXPECT_EQ(ParseLogLevel("error"), spdlog::level::err);
  EXPECT_EQ(ParseLogLevel("off"), spdlog::level::off);
  for (const char* bad : {"", "INFO", "warning", "err", "critical", "info "}) EXPECT_FALSE(ParseLogLevel(bad)) << bad;
}

// Parses `args` (without the program name) on an app with the option.
void Parse(CLI::App& app, std::vector<std::string> args) {
  std::vector<const char*> argv = {"prog"};
  for (const std::string& a : args) argv.push_back(a.c_str());
  app.parse(static_cast<int>(argv.size()), argv.data());
}

TEST(Log, OptionSetsTheLevel) {
  {
    CLI::App app;
    AddLogLevelOption(app);
    Parse(app, {});
    EXPECT_EQ(spdlog::get_level(), spdlog::level::info);  // the default
  }
  for (const auto& [name, level] : std::vector<std::pair<std::string, spdlog::level::level_enum>>{
           {"debug", spdlog::level::debug}, {"off", spdlog::level::off}, {"warn", spdlog::level::warn}}) {
    CLI::App app;
    AddLogLevelOption(app);
    Parse(app, {"--log-level", name});
    EXPECT_EQ(spdlog::get_level(), level) << name;
  }
  InitLogging(spdlog::level::info);
}

TEST(Log, OptionRefusesAnUnknownLevel) {
  CLI::App app;
  AddLogLevelOption(app);
  try {
    Parse(app, {"--log-level", "loud"});
    FAIL() << "--log-level loud was accepted";
  } catch (const CLI::ParseError& e) {
    const std::string what = e.what();
    EXPECT_NE(what.find("--log-level"), std::string::npos) << what;
    EXPECT_NE(what.find("loud"), std::string::npos) << what;
  }
  InitLogging(spdlog::level::info);
}

TEST(Log, LinesGoToStderrFromTheLevelUp) {
  InitLogging(spdlog::level::warn);
  testing::internal::CaptureStdout();
  testing::internal::CaptureStderr();
  spdlog::info("not shown {}", 1);
  spdlog::warn("shown {}", 2);
  spdlog::error("also shown");
  const std::string out = testing::internal::GetCapturedStdout();
  const std::string err = testing::internal::GetCapturedStderr();
  InitLogging(spdlog::level::info);
  EXPECT_EQ(out, "");
  EXPECT_EQ(err.find("not shown"), std::string::npos) << err;
  EXPECT_NE(err.find("[warning] shown 2\n"), std::string::npos) << err;
  EXPECT_NE(err.find("[error] also shown\n"), std::string::npos) << err;
}

TEST(Log, OffSilencesEverything) {
  InitLogging(spdlog::level::off);
  testing::internal::CaptureStderr();
  spdlog::error("an error");
  const std::string err = testing::internal::GetCapturedStderr();
  InitLogging(spdlog::level::info);
  EXPECT_EQ(err, "");
}

}  // namespace
}  // namespace holo
