#pragma once

#include <string>

namespace holo::test {

// Absolute path of a fixture in tests/data/ ("redwood/trajectory.log").
std::string TestDataPath(const std::string& relative);
// A fresh empty directory under the system temp dir, unique per call; removed
// with its contents when the test program exits (HOLO_KEEP_TEST_DIRS=1 keeps it).
std::string MakeTempDir(const std::string& prefix);

}  // namespace holo::test
