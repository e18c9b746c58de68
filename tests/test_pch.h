// Headers nearly every test compiles (gtest, Eigen through the project's
// headers, nlohmann/json, the standard library), precompiled once for all
// test programs of the sanitizer build (tests/CMakeLists.txt, HOLO_TEST_PCH). Only
// system headers: a test's own includes still name everything it uses.
#pragma once
#include <gtest/gtest.h>
#include <Eigen/Core>
#include <Eigen/Geometry>
#include <nlohmann/json.hpp>
#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <filesystem>
#include <functional>
#include <map>
#include <memory>
#include <mutex>
#include <random>
#include <set>
#include <string>
#include <thread>
#include <vector>
