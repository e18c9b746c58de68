#include <atomic>
#include <cstdlib>
#include <filesystem>
#include <mutex>
#include <random>
#include <system_error>
#include <vector>

#include <unistd.h>

#include "common/log.h"
#include "test_util.h"

namespace holo::test {

// Library log lines go to stderr in the tests too, as in the programs (spdlog's
// own default logger would write them to stdout).
[[maybe_unused]] const bool kLoggingToStderr = (InitLogging(), true);

std::string TestDataPath(const std::string& relative) { return std::string(HOLO_TEST_DATA_DIR) + "/" + relative; }

namespace {
// The directories MakeTempDir made, removed when the test program exits
// (runs of the whole suite left hundreds of them, ~0.7 GB, in /tmp);
// HOLO_KEEP_TEST_DIRS=1 keeps them for a look after a failure.
class TempDirs {
 public:
  void Add(const std::filesystem::path& dir) {
    std::lock_guard<std::mutex> lock(mu_);
    dirs_.push_back(dir);
  }
  ~TempDirs() {
    const char* keep = std::getenv("HOLO_KEEP_TEST_DIRS");
    if (keep != nullptr && *keep != '\0' && std::string(keep) != "0") return;
    for (const auto& dir : dirs_) {
      std::error_code ec;
      std::filesystem::remove_all(dir, ec);
    }
  }

 private:
  std::mutex mu_;
  std::vector<std::filesystem::path> dirs_;
};
TempDirs& Registry() {
  static TempDirs dirs;
  return dirs;
}
}  // namespace

std::string MakeTempDir(const std::string& prefix) {
  static std::atomic<int> counter{0};
  std::random_device rd;
  const auto dir = std::filesystem::temp_directory_path() /
                   (prefix + "_" + std::to_string(getpid()) + "_" + std::to_string(counter++) + "_" +
                    std::to_string(rd() % 100000));
  std::filesystem::remove_all(dir);
  std::filesystem::create_directories(dir);
  Registry().Add(dir);
  return dir.string();
}

}  // namespace holo::test
