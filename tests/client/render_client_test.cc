// holoport-client as a program: headless runs write PNGs and stats.json
// (EGL surfaceless, no X server), the mosaic has K tiles, a window without a
// display is a clear error (exit code, message), bad options are refused.
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <string>

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include "client/client_program.h"
#include "common/image_io.h"
#include "test_util.h"

namespace holo {
namespace {

using test::ClientPath;
using test::RunResult;

RunResult RunClient(const std::string& args, const std::string& env = "") {
  return test::RunCommand(env + " " + ClientPath() + " " + args);
}

TEST(RenderClientTest, ProgramExists) { ASSERT_TRUE(std::filesystem::exists(ClientPath())) << ClientPath(); }

TEST(RenderClientTest, HeadlessWritesPngsAndStats) {
  const std::string dir = test::MakeTempDir("render_client");
  // No DISPLAY: headless must not need X.
  const RunResult r = RunClient("--headless --frames 2 --width 320 --height 180 --views 4 --out " + dir, "env -u DISPLAY");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  for (const char* name : {"frame_0000.png", "frame_0001.png"}) {
    auto image = ReadImageRgb8(dir + "/" + name);
    ASSERT_TRUE(image.ok()) << image.status().ToString();
    EXPECT_EQ(image->width(), 320);
    EXPECT_EQ(image->height(), 180);
  }
  std::ifstream f(dir + "/stats.json");
  ASSERT_TRUE(f.good());
  const nlohmann::json j = nlohmann::json::parse(f);
  EXPECT_EQ(j["frames"], 2);
  EXPECT_EQ(j["views"], 4);
  EXPECT_EQ(j["mosaic"]["cols"], 2);
  EXPECT_EQ(j["mosaic"]["rows"], 2);
  EXPECT_EQ(j["mode"], "projective");
  EXPECT_GT(j["triangles"].get<int>(), 10000);
  EXPECT_GT(j["render_ms_median"].get<double>(), 0.0);
  EXPECT_GT(j["latency_ms_median"].get<double>(), j["render_ms_median"].get<double>());
  EXPECT_TRUE(j["bitrate_mbps"].is_null());
  EXPECT_EQ(j["drops"], 0);
}

TEST(RenderClientTest, WindowWithoutDisplayIsAClearError) {
  const RunResult r = RunClient("--frames 1", "env -u DISPLAY -u WAYLAND_DISPLAY");
  EXPECT_FALSE(r.signaled) << r.output;
  EXPECT_EQ(r.exit_code, 1) << r.output;
  EXPECT_NE(r.output.find("no display"), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("--headless"), std::string::npos) << r.output;
}

// The window path (GLFW, OpenGL 3.3 core) on a virtual X display the test
// starts itself with xvfb-run.
TEST(RenderClientTest, WindowUnderXvfb) {
  if (std::system("command -v xvfb-run > /dev/null 2>&1") != 0) GTEST_SKIP() << "xvfb-run is not installed (scripts/setup.sh installs xvfb); the headless EGL tests still run";
  const std::string dir = test::MakeTempDir("render_client_xvfb");
  const RunResult r = RunClient("--frames 3 --width 320 --height 240 --out " + dir,
                                "xvfb-run -a -s '-screen 0 640x480x24'");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  EXPECT_NE(r.output.find("GLFW window"), std::string::npos) << r.output;
  std::ifstream f(dir + "/stats.json");
  ASSERT_TRUE(f.good());
  const nlohmann::json j = nlohmann::json::parse(f);
  EXPECT_EQ(j["frames"], 3);
  EXPECT_EQ(j["camera"], "interactive");
}

TEST(RenderClientTest, BadOptionsAreRefused) {
  RunResult r = RunClient("--headless --views 0");
  EXPECT_NE(r.exit_code, 0);
  EXPECT_NE(r.output.find("--views"), std::string::npos) << r.output;
  r = RunClient("--headless --frames 1 --source synthetic:NOPE --out /tmp");
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_NE(r.output.find("S8-QVGA"), std::string::npos) << r.output;  // names the known workloads
  r = RunClient("--headless --frames 1 --source tcp://x --out /tmp");
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_NE(r.output.find("unknown source"), std::string::npos) << r.output;
  r = RunClient("--headless --frames 1 --pose-trace /nonexistent/trace.csv --out /tmp");
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_NE(r.output.find("--pose-trace"), std::string::npos) << r.output;
  r = RunClient("--headless --frames 1 --miniature-at 1,2 --out /tmp");
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_NE(r.output.find("--miniature-at"), std::string::npos) << r.output;
  r = RunClient("--headless --frames 1 --remote-at 1,x,0 --out /tmp");
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_NE(r.output.find("--remote-at"), std::string::npos) << r.output;
  r = RunClient("--headless --frames 1 --local /nonexistent/local.ply --out /tmp");
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_NE(r.output.find("--local"), std::string::npos) << r.output;
  r = RunClient("--help");
  EXPECT_EQ(r.exit_code, 0);
  EXPECT_NE(r.output.find("--miniature"), std::string::npos);
}

}  // namespace
}  // namespace holo
