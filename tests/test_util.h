#pragma once

#include <string>

namespace holo::test {

// Absolute path of a fixture in tests/data/ ("redwood/trajectory.log").
std::string TestDataPath(const std::string& relative);
// A fresh empty directory under the system temp dir, unique per call.
std::string MakeTempDir(const std::string& prefix);

}  // namespace holo::test
