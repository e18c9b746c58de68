#include <cmath>
#include <set>

#include <gtest/gtest.h>

#include "common/file_util.h"
#include "common/rig.h"
#include "test_util.h"

namespace holo {
namespace {

const char* kGoodRig = R"(
name: two
pods:
  - id: 0
    depth: {width: 320, height: 240, fx: 262.5, fy: 262.5, cx: 159.5, cy: 119.5}
    world_from_depth: {eye: [2, 0, 1], target: [0, 0, 1]}
  - id: 1
    depth: {width: 320, height: 240, fx: 262.5, fy: 262.5, cx: 159.5, cy: 119.5, distortion: [0.1, -0.2, 0, 0, 0.05]}
    color: {width: 640, height: 480, fx: 525, fy: 525, cx: 319.5, cy: 239.5}
    color_from_depth: {translation: [0.025, 0, 0], quaternion_wxyz: [1, 0, 0, 0]}
    world_from_depth: {translation: [0, 2, 1], quaternion_wxyz: [0.7071068, 0.7071068, 0, 0]}
)";

TEST(RigTest, ParsesPodsIntrinsicsAndPoses) {
  auto rig = ParseRigYaml(kGoodRig, "good.yaml");
  ASSERT_TRUE(rig.ok()) << rig.status().ToString();
  ASSERT_EQ(rig->pods.size(), 2u);
  EXPECT_EQ(rig->name, "two");
  EXPECT_TRUE(rig->pods[0].IsRegistered()) << "color defaults to the depth camera";
  EXPECT_FALSE(rig->pods[1].IsRegistered());
  EXPECT_DOUBLE_EQ(rig->pods[1].depth.distortion[4], 0.05);
  EXPECT_EQ(rig->pods[1].color.width, 640);
  EXPECT_NEAR(rig->pods[1].color_from_depth.translation().x(), 0.025f, 1e-6f);
  EXPECT_NEAR(rig->pods[0].world_from_depth.translation().x(), 2.0f, 1e-6f);
  EXPECT_TRUE(rig->Check().ok());
}

TEST(RigTest, YamlRoundTrip) {
  auto rig = ParseRigYaml(kGoodRig, "good.yaml");
  ASSERT_TRUE(rig.ok());
  auto again = ParseRigYaml(RigToYaml(*rig), "again.yaml");
  ASSERT_TRUE(again.ok()) << again.status().ToString();
  ASSERT_EQ(again->pods.size(), rig->pods.size());
  for (size_t i = 0; i < rig->pods.size(); ++i) {
    EXPECT_TRUE(again->pods[i].world_from_depth.matrix().isApprox(rig->pods[i].world_from_depth.matrix(), 1e-5f));
    EXPECT_TRUE(again->pods[i].color_from_depth.matrix().isApprox(rig->pods[i].color_from_depth.matrix(), 1e-5f));
    EXPECT_EQ(again->pods[i].depth.distortion, rig->pods[i].depth.distortion);
    EXPECT_EQ(again->pods[i].color.width, rig->pods[i].color.width);
  }
}

// Each bad rig must fail with a message naming the source, the key and the value.
struct BadRigCase {
  const char* yaml;
  const char* expect_key;
  const char* expect_value;
};

TEST(RigTest, ValidationErrorsNameFileKeyAndValue) {
  const BadRigCase cases[] = {
      {"pods:\n  - depth: {width: 320, height: 240, fx: -1, fy: 262.5, cx: 159.5, cy: 119.5}\n"
       "    world_from_depth: {eye: [2, 0, 1], target: [0, 0, 1]}\n",
       "pods[0].depth.fx", "-1"},
      {"pods:\n  - depth: {width: 320, height: 240, fx: abc, fy: 262.5, cx: 159.5, cy: 119.5}\n"
       "    world_from_depth: {eye: [2, 0, 1], target: [0, 0, 1]}\n",
       "pods[0].depth.fx", "abc"},
      {"pods:\n  - depth: {width: 320, height: 240, fx: 1, fy: 262.5, cx: 159.5}\n"
       "    world_from_depth: {eye: [2, 0, 1], target: [0, 0, 1]}\n",
       "pods[0].depth.cy", "missing"},
      {"pods:\n  - depth: {width: 320, height: 240, fx: 1, fy: 262.5, cx: 159.5, cy: 119.5}\n"
       "    world_from_depth: {translation: [0, 0], quaternion_wxyz: [1, 0, 0, 0]}\n",
       "pods[0].world_from_depth.translation", "[0, 0]"},
      {"pods:\n  - depth: {width: 320, height: 240, fx: 1, fy: 262.5, cx: 159.5, cy: 119.5}\n"
       "    world_from_depth: {translation: [0, 0, 0], quaternion_wxyz: [2, 0, 0, 0]}\n",
       "pods[0].world_from_depth.quaternion_wxyz", "norm 2"},
      {"pods:\n  - depth: {width: 320, height: 240, fx: 1, fy: 262.5, cx: 159.5, cy: 119.5}\n"
       "    world_from_depth: {eye: [2, 0, 1], target: [0, 0, 1]}\n"
       "  - id: 5\n    depth: {width: 320, height: 240, fx: 1, fy: 262.5, cx: 159.5, cy: 119.5}\n"
       "    world_from_depth: {eye: [2, 0, 1], target: [0, 0, 1]}\n",
       "pods[1].id", "5"},
      {"pods:\n  - depth: {width: 0, height: 240, fx: 1, fy: 262.5, cx: 159.5, cy: 119.5}\n"
       "    world_from_depth: {eye: [2, 0, 1], target: [0, 0, 1]}\n",
       "pods[0].depth.width", "0"},
      {"pods: []\n", "pods", "non-empty"},
      {"pods: [\n", "bad.yaml", "not valid YAML"},
      {"- just\n- a list\n", "bad.yaml", "top level"},
  };
  for (const auto& c : cases) {
    auto rig = ParseRigYaml(c.yaml, "bad.yaml");
    ASSERT_FALSE(rig.ok()) << c.yaml;
    const std::string& m = rig.status().message();
    EXPECT_EQ(rig.status().code(), StatusCode::kInvalidArgument);
    EXPECT_EQ(m.rfind("bad.yaml", 0), 0u) << m;
    EXPECT_NE(m.find(c.expect_key), std::string::npos) << "message: " << m;
    EXPECT_NE(m.find(c.expect_value), std::string::npos) << "message: " << m;
  }
}

TEST(RigTest, MissingFileIsNotFound) {
  auto rig = LoadRig("/nonexistent/rig.yaml");
  ASSERT_FALSE(rig.ok());
  EXPECT_EQ(rig.status().code(), StatusCode::kNotFound);
  EXPECT_NE(rig.status().message().find("/nonexistent/rig.yaml"), std::string::npos);
}

TEST(RigTest, ShippedRigsLoadAndAimAtTheCaptureVolume) {
  for (const char* name : {"studio-8", "studio-4"}) {
    auto rig = LoadRig(ShippedRigPath(name));
    ASSERT_TRUE(rig.ok()) << rig.status().ToString();
    ASSERT_TRUE(rig->Check().ok());
    EXPECT_EQ(rig->pods.size(), std::string(name) == "studio-8" ? 8u : 4u);
    std::set<int> heights_cm;
    for (const auto& pod : rig->pods) {
      const CameraModel cam = pod.DepthCamera();
      const Eigen::Vector3f c = cam.Center();
      EXPECT_NEAR(Eigen::Vector2f(c.x(), c.y()).norm(), 2.5f, 0.01f) << "ring radius";
      heights_cm.insert(static_cast<int>(std::lround(c.z() * 100)));
      // Every corner of the 2x2x2 m capture volume around (0, 0, 1) is in view.
      for (float x : {-1.0f, 1.0f})
        for (float y : {-1.0f, 1.0f})
          for (float z : {0.0f, 2.0f}) {
            (void)x;
            Eigen::Vector2f px;
            // The near corners of a 2 m cube at 2.5 m cannot all be in a 62° view;
            // require the centre column of the volume (person-sized, 1 m wide) to be.
            const Eigen::Vector3f p(0.5f * x, 0.5f * y, z * 0.95f);
            ASSERT_TRUE(cam.ProjectWorld(p, &px));
            EXPECT_GE(px.x(), 0);
            EXPECT_LT(px.x(), pod.depth.width);
            EXPECT_GE(px.y(), 0) << name << " pod " << pod.id;
            EXPECT_LT(px.y(), pod.depth.height) << name << " pod " << pod.id;
          }
    }
    EXPECT_EQ(heights_cm.size(), 2u) << "pods at two heights";
  }
}

TEST(RigTest, ScaledRigHalvesResolution) {
  auto rig = LoadRig(ShippedRigPath("studio-8"));
  ASSERT_TRUE(rig.ok());
  const Rig half = rig->Scaled(0.5);
  EXPECT_EQ(half.pods[0].depth.width, 320);
  EXPECT_EQ(half.pods[0].color.height, 240);
  EXPECT_TRUE(half.pods[0].IsRegistered());
}

}  // namespace
}  // namespace holo
