#include <atomic>
#include <filesystem>
#include <random>

#include <unistd.h>

#include "common/log.h"
#include "test_util.h"

namespace holo::test {

// Library log lines go to stderr in the tests too, as in the programs (spdlog's
// own default logger would write them to stdout).
[[maybe_unused]] const bool kLoggingToStderr = (InitLogging(), true);

std::string TestDataPath(const std::string& relative) { return std::string(HOLO_TEST_DATA_DIR) + "/" + relative; }

std::string MakeTempDir(const std::string& prefix) {
  static std::atomic<int> counter{0};
  std::random_device rd;
  const auto dir = std::filesystem::temp_directory_path() /
                   (prefix + "_" + std::to_string(getpid()) + "_" + std::to_string(counter++) + "_" +
                    std::to_string(rd() % 100000));
  std::filesystem::remove_all(dir);
  std::filesystem::create_directories(dir);
  return dir.string();
}

}  // namespace holo::test
