#include "server/capture/importers.h"

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include "common/file_util.h"
#include "common/image_io.h"
#include "test_util.h"

namespace holo {
namespace {

namespace fs = std::filesystem;

bool Contains(const Status& s, const std::string& needle) { return s.message().find(needle) != std::string::npos; }

// A writable copy of a fixture folder.
std::string CopyFixture(const std::string& name) {
  const std::string dir = test::MakeTempDir("importers") + "/" + name;
  fs::copy(test::TestDataPath(name), dir, fs::copy_options::recursive);
  for (const auto& e : fs::recursive_directory_iterator(dir))
    fs::permissions(e.path(), fs::perms::owner_write, fs::perm_options::add);
  return dir;
}

// ---------------------------------------------------------------------------
// Redwood / Open3D

TEST(ImportRedwood, IntrinsicsPosesAndDepthFromTheFixture) {
  const std::string dir = test::TestDataPath("redwood");
  auto scene = ImportRedwood(dir);
  ASSERT_TRUE(scene.ok()) << scene.status().ToString();
  ASSERT_EQ(scene->rig.pods.size(), 3u);
  ASSERT_EQ(scene->frames.frames.size(), 3u);
  EXPECT_TRUE(scene->has_poses);
  EXPECT_TRUE(scene->rig.Check().ok());
  for (const auto& pod : scene->rig.pods) {
    EXPECT_EQ(pod.depth.width, 640);
    EXPECT_EQ(pod.depth.height, 480);
    EXPECT_EQ(pod.depth.fx, 525.0);
    EXPECT_EQ(pod.depth.fy, 525.0);
    EXPECT_EQ(pod.depth.cx, 319.5);
    EXPECT_EQ(pod.depth.cy, 239.5);
    EXPECT_TRUE(pod.IsRegistered());
  }
  // trajectory.log block "1 1 2" (camera-to-world of frame 1).
  const Eigen::Matrix4f m = scene->rig.pods[1].world_from_depth.matrix();
  EXPECT_NEAR(m(0, 0), -0.2693331107603073, 1e-6);
  EXPECT_NEAR(m(0, 1), 0.03329392381977483, 1e-6);
  EXPECT_NEAR(m(0, 3), -0.31035872146799454, 1e-6);
  EXPECT_NEAR(m(1, 1), -0.9994022291201125, 1e-6);
  EXPECT_NEAR(m(1, 3), 0.5963093994288613, 1e-6);
  EXPECT_NEAR(m(2, 0), -0.9630470785211782, 1e-6);
  EXPECT_NEAR(m(2, 3), 2.126036136362892, 1e-6);
  EXPECT_EQ(scene->source_files[1], "depth/00001.png");

  // Depth is millimetres already (scale 1000): same values as the file, living-room range.
  auto raw = ReadDepth16(dir + "/depth/00002.png");
  ASSERT_TRUE(raw.ok());
  EXPECT_TRUE(scene->frames.frames[2].depth == *raw);
  std::vector<uint16_t> valid;
  for (uint16_t d : scene->frames.frames[0].depth.storage())
    if (d) valid.push_back(d);
  ASSERT_GT(valid.size(), scene->frames.frames[0].depth.num_pixels() / 2);
  std::nth_element(valid.begin(), valid.begin() + valid.size() / 2, valid.end());
  const uint16_t median = valid[valid.size() / 2];
  EXPECT_GT(median, 500);
  EXPECT_LT(median, 5000);
  // Color is real content, not black.
  double mean = 0;
  for (uint8_t c : scene->frames.frames[0].color.storage()) mean += c;
  mean /= static_cast<double>(scene->frames.frames[0].color.storage().size());
  EXPECT_GT(mean, 20);
}

// Frame 0's depth, moved into frame 1 with the imported poses, must agree with
// frame 1's depth (SOURCE.txt: median |dz| ~5 mm).
TEST(ImportRedwood, ReprojectionBetweenFramesAgrees) {
  auto scene = ImportRedwood(test::TestDataPath("redwood"));
  ASSERT_TRUE(scene.ok()) << scene.status().ToString();
  const CameraModel cam0 = scene->rig.pods[0].DepthCamera();
  const CameraModel cam1 = scene->rig.pods[1].DepthCamera();
  const ImageDepth16& d0 = scene->frames.frames[0].depth;
  const ImageDepth16& d1 = scene->frames.frames[1].depth;
  const Pose cam1_from_world = cam1.world_from_camera.inverse();
  std::vector<float> dz;
  size_t tried = 0;
  for (int y = 0; y < d0.height(); y += 2)
    for (int x = 0; x < d0.width(); x += 2) {
      if (d0.at(x, y) == 0) continue;
      ++tried;
      const Eigen::Vector3f pw = cam0.UnprojectWorld(Eigen::Vector2f(x, y), d0.at(x, y) * 1e-3f);
      Eigen::Vector2f px;
      if (!cam1.ProjectWorld(pw, &px)) continue;
      const int u = static_cast<int>(std::lround(px.x())), v = static_cast<int>(std::lround(px.y()));
      if (!d1.Contains(u, v) || d1.at(u, v) == 0) continue;
      const float z1 = (cam1_from_world * pw).z();
      dz.push_back(std::abs(z1 - d1.at(u, v) * 1e-3f));
    }
  ASSERT_GT(dz.size(), tried / 2);
  std::nth_element(dz.begin(), dz.begin() + dz.size() / 2, dz.end());
  const float median = dz[dz.size() / 2];
  EXPECT_LT(median, 0.02f);
  // And the poses matter: with frame 0's pose for both, the error is much larger.
  std::vector<float> dz_wrong;
  const Pose cam0_from_world = cam0.world_from_camera.inverse();
  for (int y = 0; y < d0.height(); y += 2)
    for (int x = 0; x < d0.width(); x += 2) {
      if (d0.at(x, y) == 0) continue;
      const Eigen::Vector3f pw = cam0.UnprojectWorld(Eigen::Vector2f(x, y), d0.at(x, y) * 1e-3f);
      Eigen::Vector2f px;
      if (!cam0.ProjectWorld(pw, &px)) continue;
      const int u = static_cast<int>(std::lround(px.x())), v = static_cast<int>(std::lround(px.y()));
      if (!d1.Contains(u, v) || d1.at(u, v) == 0) continue;
      dz_wrong.push_back(std::abs((cam0_from_world * pw).z() - d1.at(u, v) * 1e-3f));
    }
  std::nth_element(dz_wrong.begin(), dz_wrong.begin() + dz_wrong.size() / 2, dz_wrong.end());
  EXPECT_GT(dz_wrong[dz_wrong.size() / 2], median);
  RecordProperty("median_dz_mm", std::to_string(median * 1000));
}

TEST(ImportRedwood, FrameSelectionAndOptions) {
  RedwoodImportOptions opt;
  opt.frames = {2, 0};
  auto scene = ImportRedwood(test::TestDataPath("redwood"), opt);
  ASSERT_TRUE(scene.ok()) << scene.status().ToString();
  ASSERT_EQ(scene->rig.pods.size(), 2u);
  EXPECT_EQ(scene->rig.pods[0].id, 0);
  EXPECT_EQ(scene->frames.frames[1].pod_id, 1);
  EXPECT_NEAR(scene->rig.pods[0].world_from_depth.translation().y(), 0.6204495589484211, 1e-6);
  EXPECT_NEAR(scene->rig.pods[1].world_from_depth.translation().y(), 0.5730122438481298, 1e-6);

  opt.frames = {3};
  auto bad = ImportRedwood(test::TestDataPath("redwood"), opt);
  ASSERT_FALSE(bad.ok());
  EXPECT_TRUE(Contains(bad.status(), "options.frames[0] = 3 is out of range")) << bad.status().message();

  // Intrinsics from the options, no trajectory.
  RedwoodImportOptions o2;
  Intrinsics k;
  k.width = 640;
  k.height = 480;
  k.fx = k.fy = 500;
  k.cx = 320;
  k.cy = 240;
  o2.intrinsics = k;
  o2.trajectory_file = "";
  auto s2 = ImportRedwood(test::TestDataPath("redwood"), o2);
  ASSERT_TRUE(s2.ok()) << s2.status().ToString();
  EXPECT_EQ(s2->rig.pods[0].depth.fx, 500);
  EXPECT_FALSE(s2->has_poses);
  EXPECT_TRUE(s2->rig.pods[2].world_from_depth.isApprox(Pose::Identity()));
}

TEST(ImportRedwood, MalformedFoldersNameTheFile) {
  {
    const std::string dir = CopyFixture("redwood");
    fs::remove(dir + "/camera_intrinsic.json");
    auto s = ImportRedwood(dir);
    ASSERT_FALSE(s.ok());
    EXPECT_EQ(s.status().code(), StatusCode::kNotFound);
    EXPECT_TRUE(Contains(s.status(), dir + "/camera_intrinsic.json")) << s.status().message();
  }
  const std::vector<std::pair<std::string, std::string>> bad_json = {
      {"{ \"width\": 640, ", "not valid JSON"},
      {"[1, 2]", "expected a JSON object"},
      {"{\"width\": 640, \"height\": 480}", "missing 'intrinsic_matrix'"},
      {"{\"width\": -5, \"height\": 480, \"intrinsic_matrix\": [525,0,0,0,525,0,319.5,239.5,1]}", "'width' must be"},
      {"{\"width\": 640, \"height\": 480, \"intrinsic_matrix\": [525,0,0,0,525,0,319.5,239.5]}", "'intrinsic_matrix' must be an array of 9"},
      {"{\"width\": 640, \"height\": 480, \"intrinsic_matrix\": [525,0,0,0,525,0,319.5,\"a\",1]}", "intrinsic_matrix[7] is not a number"},
      {"{\"width\": 640, \"height\": 480, \"intrinsic_matrix\": [525,0,319.5,0,525,239.5,0,0,1]}", "intrinsic_matrix is not a pinhole"},
  };
  for (const auto& [text, expect] : bad_json) {
    auto k = ParseOpen3dIntrinsicJson(text, "cam.json");
    ASSERT_FALSE(k.ok()) << text;
    EXPECT_TRUE(Contains(k.status(), "cam.json: " + expect)) << k.status().message();
  }
  {
    // Wrong image size.
    const std::string dir = CopyFixture("redwood");
    ASSERT_TRUE(WriteDepth16(dir + "/depth/00001.png", ImageDepth16(320, 240, 1000)).ok());
    auto s = ImportRedwood(dir);
    ASSERT_FALSE(s.ok());
    EXPECT_EQ(s.status().message(),
              dir + "/depth/00001.png: image is 320x240, " + dir + "/camera_intrinsic.json says 640x480");
  }
  {
    // 8-bit depth.
    const std::string dir = CopyFixture("redwood");
    ASSERT_TRUE(WriteMask8(dir + "/depth/00002.png", ImageGray8(640, 480, 3)).ok());
    auto s = ImportRedwood(dir);
    ASSERT_FALSE(s.ok());
    EXPECT_EQ(s.status().message(), dir + "/depth/00002.png: depth must be a 16-bit single-channel PNG, got 8-bit");
  }
  {
    // Count mismatch between images.
    const std::string dir = CopyFixture("redwood");
    fs::remove(dir + "/color/00002.jpg");
    auto s = ImportRedwood(dir);
    ASSERT_FALSE(s.ok());
    EXPECT_TRUE(Contains(s.status(), dir + "/color: 2 images, but " + dir + "/depth has 3")) << s.status().message();
  }
  {
    // Count mismatch between images and poses.
    const std::string dir = CopyFixture("redwood");
    auto text = ReadFileToString(dir + "/trajectory.log");
    ASSERT_TRUE(text.ok());
    size_t cut = 0;
    for (int i = 0; i < 10; ++i) cut = text->find('\n', cut) + 1;  // keep 2 blocks
    ASSERT_TRUE(WriteStringToFile(dir + "/trajectory.log", text->substr(0, cut)).ok());
    auto s = ImportRedwood(dir);
    ASSERT_FALSE(s.ok());
    EXPECT_TRUE(Contains(s.status(), dir + "/trajectory.log: 2 poses for 3 images")) << s.status().message();
  }
}

TEST(ParseRedwoodTrajectory, BadLinesAndEveryTruncation) {
  auto text = ReadFileToString(test::TestDataPath("redwood/trajectory.log"));
  ASSERT_TRUE(text.ok());
  auto poses = ParseRedwoodTrajectory(*text, "t.log");
  ASSERT_TRUE(poses.ok());
  ASSERT_EQ(poses->size(), 3u);
  EXPECT_NEAR(poses->at(2).translation().z(), 2.1247894438735306, 1e-6);

  const std::vector<std::pair<std::string, std::string>> cases = {
      {"0 0 1\n1 0 0 0\n0 1 0 0\n0 0 1 0\n", "t.log:1: truncated: the block has 3 of 4 matrix rows"},
      {"0 0\n", "t.log:1: expected a block header of 3 integers"},
      {"0 0 1\n1 0 0 0\n0 1 0 abc\n0 0 1 0\n0 0 0 1\n", "t.log:3: not a number: 'abc'"},
      {"0 0 1\n1 0 0 0\n0 1 0\n0 0 1 0\n0 0 0 1\n", "t.log:3: expected 4 numbers in matrix row 2, got 3"},
      {"0 0 1\n1 0 0 0\n0 1 0 0\n0 0 1 0\n0 0 1 1\n", "t.log:1: last matrix row must be 0 0 0 1"},
      {"0 0 1\n2 0 0 0\n0 1 0 0\n0 0 1 0\n0 0 0 1\n", "t.log:1: matrix is not a rigid transform"},
      {"0 0 1\n-1 0 0 0\n0 1 0 0\n0 0 1 0\n0 0 0 1\n", "t.log:1: matrix is not a rigid transform"},
      {"0 0 1\n1 0 0 nan\n0 1 0 0\n0 0 1 0\n0 0 0 1\n", "t.log:2: not a number"},
  };
  for (const auto& [t, expect] : cases) {
    auto p = ParseRedwoodTrajectory(t, "t.log");
    ASSERT_FALSE(p.ok()) << t;
    EXPECT_TRUE(Contains(p.status(), expect)) << p.status().message();
  }
  // Every prefix: an error or fewer whole poses, never a crash.
  for (size_t n = 0; n < text->size(); ++n) {
    const std::string prefix = text->substr(0, n);
    auto p = ParseRedwoodTrajectory(prefix, "t.log");
    if (p.ok()) {
      EXPECT_LE(p->size(), 3u);
    }
  }
}

// ---------------------------------------------------------------------------
// TUM

TEST(ImportTum, FixtureIntrinsicsDepthScaleAndPose) {
  const std::string dir = test::TestDataPath("tum");
  auto scene = ImportTum(dir);
  ASSERT_TRUE(scene.ok()) << scene.status().ToString();
  ASSERT_EQ(scene->rig.pods.size(), 1u);
  const auto& pod = scene->rig.pods[0];
  EXPECT_EQ(pod.depth.width, 640);
  EXPECT_EQ(pod.depth.height, 480);
  EXPECT_EQ(pod.depth.fx, 525.0);
  EXPECT_EQ(pod.depth.cx, 319.5);
  EXPECT_EQ(pod.color.cy, 239.5);
  EXPECT_TRUE(scene->has_poses);
  EXPECT_TRUE(pod.world_from_depth.isApprox(Pose::Identity()));  // the made-up identity pose
  const RgbdFrame& f = scene->frames.frames[0];
  EXPECT_EQ(f.timestamp_us, 1341847980723020);
  EXPECT_EQ(scene->source_files[0], "depth/1341847980.723020.png");

  // Depth converted from 5000 units/m to mm: d_mm = round(d / 5), pixel by pixel.
  auto raw = ReadDepth16(dir + "/depth/1341847980.723020.png");
  ASSERT_TRUE(raw.ok());
  const uint16_t r = raw->at(320, 240);
  ASSERT_GT(r, 0);
  EXPECT_EQ(f.depth.at(320, 240), static_cast<uint16_t>(std::lround(r / 5.0)));
  size_t valid = 0, mismatches = 0;
  for (size_t i = 0; i < raw->storage().size(); ++i) {
    valid += raw->storage()[i] != 0;
    mismatches += f.depth.storage()[i] != static_cast<uint16_t>(std::lround(raw->storage()[i] / 5.0));
  }
  EXPECT_EQ(mismatches, 0u);
  // SOURCE.txt: about 19% missing.
  EXPECT_NEAR(1.0 - static_cast<double>(valid) / raw->num_pixels(), 0.19, 0.03);
  // Desk scene: depth in the 0.5-5 m range at the centre.
  EXPECT_GT(f.depth.at(320, 240), 500);
  EXPECT_LT(f.depth.at(320, 240), 5000);
  auto rgb = ReadImageRgb8(dir + "/rgb/1341847980.722988.png");
  ASSERT_TRUE(rgb.ok());
  EXPECT_TRUE(f.color == *rgb);

  auto fr3 = ImportTum(dir, TumImportOptions::Freiburg(3));
  ASSERT_TRUE(fr3.ok());
  EXPECT_EQ(fr3->rig.pods[0].depth.fx, 535.4);
  EXPECT_EQ(fr3->rig.pods[0].depth.cy, 247.6);

  // The rgb is 32 µs from the depth: a tighter limit finds no pair.
  TumImportOptions tight;
  tight.max_time_difference_s = 1e-5;
  auto none = ImportTum(dir, tight);
  ASSERT_FALSE(none.ok());
  EXPECT_TRUE(Contains(none.status(), dir + "/depth.txt: no depth image has an rgb.txt image within"));
}

// A small synthetic TUM folder: tiny images, several timestamps, two poses.
class TumSynthetic : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = test::MakeTempDir("tum_synth");
    fs::create_directories(dir_ + "/rgb");
    fs::create_directories(dir_ + "/depth");
    for (const char* t : {"1.001000", "1.051000", "1.200000"})
      ASSERT_TRUE(WriteImageRgb8(dir_ + "/rgb/" + t + ".png", ImageRgb8(8, 6, 100)).ok());
    int i = 0;
    for (const char* t : {"1.000000", "1.050000", "1.300000"}) {
      ImageDepth16 d(8, 6, static_cast<uint16_t>(5000 * (i + 1)));
      d.at(0, 0) = 65535;
      d.at(1, 0) = 2;  // 0.4 mm rounds to 0
      d.at(2, 0) = 3;  // 0.6 mm rounds to 1
      ASSERT_TRUE(WriteDepth16(dir_ + "/depth/" + t + ".png", d).ok());
      ++i;
    }
    Write("rgb.txt", "# color images\n# timestamp filename\n1.001000 rgb/1.001000.png\n"
                     "1.051000 rgb/1.051000.png\n1.200000 rgb/1.200000.png\n");
    Write("depth.txt", "# depth maps\n1.050000 depth/1.050000.png\n1.000000 depth/1.000000.png\n"
                       "1.300000 depth/1.300000.png\n");
    // Quarter turn about z and 1 m along x between t = 1.01 and t = 1.09.
    Write("groundtruth.txt", "# timestamp tx ty tz qx qy qz qw\n1.01 0 0 0 0 0 0 1\n"
                             "1.09 1 0 0 0 0 0.7071067811865476 0.7071067811865476\n");
    // Intrinsics that fit the 8x6 images.
    options_.fx = options_.fy = 6.0;
    options_.cx = 3.5;
    options_.cy = 2.5;
  }
  void Write(const std::string& name, const std::string& text) {
    ASSERT_TRUE(WriteStringToFile(dir_ + "/" + name, text).ok());
  }
  std::string dir_;
  TumImportOptions options_;
};

TEST_F(TumSynthetic, AssociationInterpolationAndScale) {
  auto scene = ImportTum(dir_, options_);
  ASSERT_TRUE(scene.ok()) << scene.status().ToString();
  // depth 1.3 has no rgb within 0.02 s.
  ASSERT_EQ(scene->rig.pods.size(), 2u);
  EXPECT_EQ(scene->frames.frames[0].timestamp_us, 1'000'000);
  EXPECT_EQ(scene->frames.frames[1].timestamp_us, 1'050'000);
  EXPECT_EQ(scene->frames.frames[0].depth.at(5, 5), 1000);
  EXPECT_EQ(scene->frames.frames[1].depth.at(5, 5), 2000);
  EXPECT_EQ(scene->frames.frames[0].depth.at(0, 0), 13107);
  EXPECT_EQ(scene->frames.frames[0].depth.at(1, 0), 0);
  EXPECT_EQ(scene->frames.frames[0].depth.at(2, 0), 1);
  EXPECT_EQ(scene->rig.pods[0].depth.width, 8);
  // t = 1.05 is halfway between 1.01 and 1.09: 0.5 m along x, 45° about z.
  const Pose& p = scene->rig.pods[1].world_from_depth;
  EXPECT_NEAR(p.translation().x(), 0.5, 1e-6);
  EXPECT_NEAR(Eigen::AngleAxisf(p.linear()).angle(), M_PI / 4, 1e-5);
  EXPECT_TRUE(scene->rig.pods[0].world_from_depth.isApprox(Pose::Identity()));

  TumImportOptions opt = options_;
  opt.frames = {1};
  auto one = ImportTum(dir_, opt);
  ASSERT_TRUE(one.ok());
  EXPECT_EQ(one->frames.frames[0].timestamp_us, 1'050'000);

  // Depth 1.3 gets a pair with a looser limit, but no pose within 0.05 s.
  opt.frames = {};
  opt.max_time_difference_s = 0.2;
  auto far = ImportTum(dir_, opt);
  ASSERT_FALSE(far.ok());
  EXPECT_TRUE(Contains(far.status(), dir_ + "/groundtruth.txt: no pose within")) << far.status().message();
}

TEST_F(TumSynthetic, MalformedFilesNameFileAndLine) {
  Write("rgb.txt", "# c\n1.0 rgb/1.001000.png\n1.05\n");
  auto s = ImportTum(dir_, options_);
  ASSERT_FALSE(s.ok());
  EXPECT_TRUE(Contains(s.status(), dir_ + "/rgb.txt:3: expected 'timestamp filename'")) << s.status().message();

  Write("rgb.txt", "abc rgb/1.001000.png\n");
  s = ImportTum(dir_, options_);
  EXPECT_TRUE(Contains(s.status(), dir_ + "/rgb.txt:1: bad timestamp 'abc'")) << s.status().message();

  Write("rgb.txt", "1.001 ../../etc/passwd\n");
  s = ImportTum(dir_, options_);
  EXPECT_TRUE(Contains(s.status(), "must be a relative path inside the folder")) << s.status().message();

  Write("rgb.txt", "1.001000 rgb/missing.png\n");
  s = ImportTum(dir_, options_);
  EXPECT_EQ(s.status().code(), StatusCode::kNotFound);
  EXPECT_TRUE(Contains(s.status(), dir_ + "/rgb/missing.png")) << s.status().message();

  Write("rgb.txt", "1.001000 rgb/1.001000.png\n");
  Write("groundtruth.txt", "1.0 0 0 0 0 0 0 2\n");
  s = ImportTum(dir_, options_);
  EXPECT_TRUE(Contains(s.status(), dir_ + "/groundtruth.txt:1: quaternion is not unit length")) << s.status().message();
  Write("groundtruth.txt", "1.0 0 0 0 0 0 1\n");
  s = ImportTum(dir_, options_);
  EXPECT_TRUE(Contains(s.status(), dir_ + "/groundtruth.txt:1: expected 'timestamp tx ty tz qx qy qz qw'"));

  fs::remove(dir_ + "/groundtruth.txt");
  auto no_gt = ImportTum(dir_, options_);
  ASSERT_TRUE(no_gt.ok()) << no_gt.status().ToString();
  EXPECT_FALSE(no_gt->has_poses);
  TumImportOptions req = options_;
  req.require_poses = true;
  s = ImportTum(dir_, req);
  EXPECT_EQ(s.status().code(), StatusCode::kNotFound);
  EXPECT_TRUE(Contains(s.status(), dir_ + "/groundtruth.txt"));

  ASSERT_TRUE(WriteMask8(dir_ + "/depth/1.000000.png", ImageGray8(8, 6)).ok());
  s = ImportTum(dir_, options_);
  EXPECT_EQ(s.status().message(), dir_ + "/depth/1.000000.png: depth must be a 16-bit single-channel PNG, got 8-bit");

  ASSERT_TRUE(WriteDepth16(dir_ + "/depth/1.000000.png", ImageDepth16(8, 6)).ok());
  ASSERT_TRUE(WriteImageRgb8(dir_ + "/rgb/1.001000.png", ImageRgb8(9, 6)).ok());
  s = ImportTum(dir_, options_);
  EXPECT_EQ(s.status().message(), dir_ + "/rgb/1.001000.png: image is 9x6, its depth image says 8x6");

  fs::remove(dir_ + "/depth.txt");
  s = ImportTum(dir_, options_);
  EXPECT_EQ(s.status().code(), StatusCode::kNotFound);
  EXPECT_TRUE(Contains(s.status(), dir_ + "/depth.txt"));

  TumImportOptions bad = options_;
  bad.fx = -1;
  s = ImportTum(dir_, bad);
  EXPECT_TRUE(Contains(s.status(), "fx must be > 0")) << s.status().message();
}

// ---------------------------------------------------------------------------
// MemoryFrameSource

TEST(MemoryFrameSource, ServesAnImportedScene) {
  auto scene = ImportRedwood(test::TestDataPath("redwood"));
  ASSERT_TRUE(scene.ok());
  const ImageDepth16 depth2 = scene->frames.frames[2].depth;
  auto src = MemoryFrameSource::FromScene(std::move(*scene));
  ASSERT_TRUE(src.ok()) << src.status().ToString();
  FrameSource& s = **src;
  EXPECT_EQ(s.num_frames(), 1);
  EXPECT_EQ(s.rig().pods.size(), 3u);
  RgbdFrameSet set;
  ASSERT_TRUE(s.Next(&set).ok());
  ASSERT_EQ(set.frames.size(), 3u);
  EXPECT_TRUE(set.frames[2].depth == depth2);
  EXPECT_EQ(s.Next(&set).code(), StatusCode::kOutOfRange);
  ASSERT_TRUE(s.Seek(0).ok());
  EXPECT_TRUE(s.Next(&set).ok());
  EXPECT_EQ(s.Seek(1).code(), StatusCode::kOutOfRange);
}

TEST(MemoryFrameSource, RejectsSetsThatDoNotMatchTheRig) {
  Rig rig;
  PodCalibration pod;
  pod.depth = Intrinsics::FromFov(8, 6, 60);
  pod.color = pod.depth;
  rig.pods.push_back(pod);
  RgbdFrameSet set;
  set.frames.resize(1);
  set.frames[0].color.Resize(8, 6);
  set.frames[0].depth.Resize(8, 5);
  auto src = MemoryFrameSource::Create(rig, {set});
  ASSERT_FALSE(src.ok());
  EXPECT_TRUE(Contains(src.status(), "frame set 0 pod 0: depth size differs from the rig"));
  set.frames[0].depth.Resize(8, 6);
  EXPECT_TRUE(MemoryFrameSource::Create(rig, {set}).ok());
}

}  // namespace
}  // namespace holo
