#include <atomic>
#include <filesystem>
#include <random>

#include <unistd.h>

#include "test_util.h"

namespace holo::test {

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
