// The PLY fuzz target's corpus (protocol/fuzz/corpus/ply/: seeds plus inputs a
// fuzz run found) through ReadPly: seeds read, every mesh read validates
// (normals included), crash inputs are refused with an error naming the cause.
#include <gtest/gtest.h>

#include <filesystem>

#include "common/mesh.h"

namespace holo {
namespace {

const std::string kCorpusDir = std::string(HOLO_SOURCE_DIR) + "/protocol/fuzz/corpus/ply";

TEST(PlyFuzzCorpus, SeedsReadCrashesRefused) {
  int seeds = 0, crashes = 0;
  for (const auto& entry : std::filesystem::directory_iterator(kCorpusDir)) {
    if (!entry.is_regular_file()) continue;
    const std::string name = entry.path().filename().string();
    auto mesh = ReadPly(entry.path().string());
    if (mesh.ok()) {
      EXPECT_TRUE(mesh->Validate().ok()) << name;
      for (const auto& n : mesh->normals) EXPECT_TRUE(n.allFinite()) << name;
    }
    if (name.rfind("seed-", 0) == 0) {
      EXPECT_TRUE(mesh.ok()) << name << ": " << mesh.status().ToString();
      ++seeds;
    }
    if (name.rfind("crash-", 0) == 0) {
      EXPECT_FALSE(mesh.ok()) << name;
      ++crashes;
    }
  }
  EXPECT_GE(seeds, 3);
  EXPECT_GE(crashes, 1);
}

TEST(PlyFuzzCorpus, NonFiniteNormalIsNamed) {
  auto mesh = ReadPly(kCorpusDir + "/crash-nonfinite-normal.ply");
  ASSERT_FALSE(mesh.ok());
  EXPECT_NE(mesh.status().ToString().find("normal"), std::string::npos) << mesh.status().ToString();
  EXPECT_NE(mesh.status().ToString().find("not finite"), std::string::npos) << mesh.status().ToString();
}

}  // namespace
}  // namespace holo
