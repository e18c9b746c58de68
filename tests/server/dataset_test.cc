#include "server/capture/dataset.h"

#include <filesystem>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include "common/file_util.h"
#include "common/image_io.h"
#include "test_util.h"

namespace holo {
namespace {

// Two pods; depth and color differ in size so that a swapped check shows.
Rig SyntheticRig() {
  Rig rig;
  rig.name = "synthetic";
  for (int k = 0; k < 2; ++k) {
    PodCalibration pod;
    pod.id = k;
    pod.name = "pod" + std::to_string(k);
    pod.depth = Intrinsics::FromFov(32, 24, 70);
    pod.color = Intrinsics::FromFov(40, 30, 65);
    pod.world_from_depth = LookAt(Eigen::Vector3f(2.0f * (k ? 1 : -1), 0.5f, 1.5f), Eigen::Vector3f(0, 0, 1));
    rig.pods.push_back(pod);
  }
  return rig;
}

// A frame set filled with a pattern that depends on frame, pod and pixel.
RgbdFrameSet Pattern(const Rig& rig, int64_t frame, bool masks) {
  RgbdFrameSet set;
  set.frame_index = frame;
  for (const auto& pod : rig.pods) {
    RgbdFrame f;
    f.pod_id = pod.id;
    f.timestamp_us = 1'000'000 + frame * 33'333 + pod.id * 7;
    f.color.Resize(pod.color.width, pod.color.height);
    for (int y = 0; y < f.color.height(); ++y)
      for (int x = 0; x < f.color.width(); ++x)
        for (int c = 0; c < 3; ++c) f.color.at(x, y, c) = static_cast<uint8_t>(x * 5 + y * 3 + c * 70 + frame * 11 + pod.id);
    f.depth.Resize(pod.depth.width, pod.depth.height);
    for (int y = 0; y < f.depth.height(); ++y)
      for (int x = 0; x < f.depth.width(); ++x)
        f.depth.at(x, y) = (x + y) % 7 == 0 ? 0 : static_cast<uint16_t>(500 + x * 97 + y * 1009 + frame * 3 + pod.id * 60000 % 4000);
    if (masks && pod.id == 0) {
      f.mask.Resize(pod.depth.width, pod.depth.height);
      for (int y = 0; y < f.mask.height(); ++y)
        for (int x = 0; x < f.mask.width(); ++x) f.mask.at(x, y) = (x > 10 && y > 5 + frame) ? 255 : 0;
    }
    set.frames.push_back(std::move(f));
  }
  return set;
}

void ExpectSetEq(const RgbdFrameSet& a, const RgbdFrameSet& b) {
  EXPECT_EQ(a.frame_index, b.frame_index);
  ASSERT_EQ(a.frames.size(), b.frames.size());
  for (size_t k = 0; k < a.frames.size(); ++k) {
    EXPECT_EQ(a.frames[k].pod_id, b.frames[k].pod_id);
    EXPECT_EQ(a.frames[k].timestamp_us, b.frames[k].timestamp_us);
    EXPECT_TRUE(a.frames[k].color == b.frames[k].color) << "pod " << k << " color";
    EXPECT_TRUE(a.frames[k].depth == b.frames[k].depth) << "pod " << k << " depth";
    EXPECT_TRUE(a.frames[k].mask == b.frames[k].mask) << "pod " << k << " mask";
  }
}

bool Contains(const Status& s, const std::string& needle) { return s.message().find(needle) != std::string::npos; }

// Writes frames 0, 1, 5 (a gap is allowed: frame numbers only have to increase).
std::vector<RgbdFrameSet> WriteDataset(const std::string& dir, DatasetWriterOptions options = {}) {
  const Rig rig = SyntheticRig();
  auto w = DatasetWriter::Create(dir, rig, options);
  EXPECT_TRUE(w.ok()) << w.status().ToString();
  std::vector<RgbdFrameSet> sets;
  for (int64_t f : {0, 1, 5}) {
    sets.push_back(Pattern(rig, f, /*masks=*/f != 1));
    EXPECT_TRUE((*w)->Write(sets.back()).ok());
  }
  EXPECT_TRUE((*w)->Close().ok());
  return sets;
}

TEST(Dataset, WriteReadRoundTripIsExact) {
  const std::string dir = test::MakeTempDir("dataset") + "/rec";
  const auto sets = WriteDataset(dir);
  auto r = DatasetReader::Open(dir);
  ASSERT_TRUE(r.ok()) << r.status().ToString();
  DatasetReader& reader = **r;
  EXPECT_EQ(reader.num_frames(), 3);
  const Rig rig = SyntheticRig();
  ASSERT_EQ(reader.rig().pods.size(), 2u);
  for (size_t k = 0; k < 2; ++k) {
    EXPECT_EQ(reader.rig().pods[k].depth.width, 32);
    EXPECT_EQ(reader.rig().pods[k].color.height, 30);
    EXPECT_NEAR(reader.rig().pods[k].depth.fx, rig.pods[k].depth.fx, 1e-6);
    EXPECT_TRUE(reader.rig().pods[k].world_from_depth.isApprox(rig.pods[k].world_from_depth, 1e-5f));
  }
  RgbdFrameSet got;
  for (const auto& want : sets) {
    ASSERT_TRUE(reader.Next(&got).ok());
    ExpectSetEq(got, want);
  }
  EXPECT_EQ(reader.Next(&got).code(), StatusCode::kOutOfRange);
  ASSERT_TRUE(reader.Seek(1).ok());
  ASSERT_TRUE(reader.Next(&got).ok());  // reuses buffers of a set that had masks
  ExpectSetEq(got, sets[1]);
  EXPECT_TRUE(got.frames[0].mask.empty());
  ASSERT_TRUE(reader.Read(2, &got).ok());
  ExpectSetEq(got, sets[2]);
  EXPECT_EQ(reader.Seek(3).code(), StatusCode::kOutOfRange);
  EXPECT_EQ(reader.Seek(-1).code(), StatusCode::kOutOfRange);
  EXPECT_EQ(reader.Read(3, &got).code(), StatusCode::kOutOfRange);
  EXPECT_FALSE(reader.has_ground_truth());

  // The FrameSource interface sees the same thing.
  FrameSource& src = reader;
  ASSERT_TRUE(src.Seek(0).ok());
  ASSERT_TRUE(src.Next(&got).ok());
  ExpectSetEq(got, sets[0]);

  auto csv = ReadFileToString(dir + "/frames.csv");
  ASSERT_TRUE(csv.ok());
  EXPECT_EQ(csv->substr(0, 23), "frame,pod,timestamp_us\n");
  EXPECT_TRUE(FileExists(dir + "/pod1/depth/000005.png"));
  EXPECT_TRUE(FileExists(dir + "/pod0/mask/000005.png"));
  EXPECT_FALSE(FileExists(dir + "/pod1/mask/000005.png"));
}

TEST(Dataset, JpegColorIsCloseDepthStaysExact) {
  const std::string dir = test::MakeTempDir("dataset") + "/rec";
  DatasetWriterOptions opt;
  opt.color_jpeg = true;
  opt.jpeg_quality = 97;
  const auto sets = WriteDataset(dir, opt);
  EXPECT_TRUE(FileExists(dir + "/pod0/color/000000.jpg"));
  auto r = DatasetReader::Open(dir);
  ASSERT_TRUE(r.ok());
  RgbdFrameSet got;
  ASSERT_TRUE((*r)->Read(0, &got).ok());
  EXPECT_TRUE(got.frames[1].depth == sets[0].frames[1].depth);
  double err = 0;
  const auto& a = got.frames[1].color.storage();
  const auto& b = sets[0].frames[1].color.storage();
  for (size_t i = 0; i < a.size(); ++i) err += std::abs(int(a[i]) - int(b[i]));
  // The pattern wraps around every few pixels (sharp edges) and JPEG subsamples chroma 4:2:0,
  // so the error is far above that of a natural image; it still must be small against 255.
  EXPECT_LT(err / static_cast<double>(a.size()), 12.0);
}

TEST(Dataset, GroundTruthRoundTrip) {
  const std::string dir = test::MakeTempDir("dataset") + "/rec";
  const Rig rig = SyntheticRig();
  auto w = DatasetWriter::Create(dir, rig);
  ASSERT_TRUE(w.ok());
  const RgbdFrameSet set = Pattern(rig, 0, true);
  ASSERT_TRUE((*w)->Write(set).ok());
  std::vector<ImageDepth16> depth = {set.frames[0].depth, set.frames[1].depth};
  depth[1].at(3, 3) = 4321;
  std::vector<ImageGray8> masks = {ImageGray8(32, 24, 255), ImageGray8(32, 24, 0)};
  Mesh mesh;
  mesh.positions = {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}};
  mesh.triangles = {{0, 1, 2}};
  ASSERT_TRUE((*w)->WriteGroundTruth(0, depth, masks, &mesh).ok());
  EXPECT_FALSE((*w)->WriteGroundTruth(0, {ImageDepth16(3, 3)}, {}, nullptr).ok());  // 1 image for 2 pods
  ASSERT_TRUE((*w)->Close().ok());

  auto r = DatasetReader::Open(dir);
  ASSERT_TRUE(r.ok());
  EXPECT_TRUE((*r)->has_ground_truth());
  std::vector<ImageDepth16> gd;
  std::vector<ImageGray8> gm;
  ASSERT_TRUE((*r)->ReadGroundTruthDepth(0, &gd, &gm).ok());
  ASSERT_EQ(gd.size(), 2u);
  EXPECT_TRUE(gd[1] == depth[1]);
  EXPECT_TRUE(gm[0] == masks[0]);
  auto m = (*r)->ReadGroundTruthMesh(0);
  ASSERT_TRUE(m.ok()) << m.status().ToString();
  EXPECT_EQ(m->positions, mesh.positions);
  EXPECT_EQ(m->triangles, mesh.triangles);
}

TEST(Dataset, WriterRefusesBadInput) {
  const std::string dir = test::MakeTempDir("dataset") + "/rec";
  const Rig rig = SyntheticRig();
  auto w = DatasetWriter::Create(dir, rig);
  ASSERT_TRUE(w.ok());
  // A second writer on the same folder.
  auto again = DatasetWriter::Create(dir, rig);
  ASSERT_FALSE(again.ok());
  EXPECT_TRUE(Contains(again.status(), "already holds a dataset"));

  RgbdFrameSet set = Pattern(rig, 3, false);
  set.frames[1].depth.Resize(31, 24);
  Status s = (*w)->Write(set);
  EXPECT_TRUE(Contains(s, "pod 1 depth: image is 31x24, rig says 32x24")) << s.message();
  set = Pattern(rig, 3, false);
  set.frames.pop_back();
  EXPECT_FALSE((*w)->Write(set).ok());
  ASSERT_TRUE((*w)->Write(Pattern(rig, 3, false)).ok());
  s = (*w)->Write(Pattern(rig, 3, false));
  EXPECT_TRUE(Contains(s, "frame numbers must increase")) << s.message();
  Rig empty;
  EXPECT_FALSE(DatasetWriter::Create(dir + "2", empty).ok());
}

// ---------------------------------------------------------------------------
// Malformed datasets: every error names the file.

class MalformedDataset : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = test::MakeTempDir("dataset_bad") + "/rec";
    sets_ = WriteDataset(dir_);
  }
  Status OpenStatus() {
    auto r = DatasetReader::Open(dir_);
    return r.ok() ? OkStatus() : r.status();
  }
  Status ReadStatus(int64_t index) {
    auto r = DatasetReader::Open(dir_);
    if (!r.ok()) return r.status();
    RgbdFrameSet set;
    return (*r)->Read(index, &set);
  }
  void WriteCsv(const std::string& text) { ASSERT_TRUE(WriteStringToFile(dir_ + "/frames.csv", text).ok()); }
  std::string dir_;
  std::vector<RgbdFrameSet> sets_;
};

TEST_F(MalformedDataset, MissingRigYaml) {
  std::filesystem::remove(dir_ + "/rig.yaml");
  const Status s = OpenStatus();
  EXPECT_EQ(s.code(), StatusCode::kNotFound);
  EXPECT_TRUE(Contains(s, dir_ + "/rig.yaml")) << s.message();
}

TEST_F(MalformedDataset, BadYaml) {
  ASSERT_TRUE(WriteStringToFile(dir_ + "/rig.yaml", "name: x\npods: [ {id: 0, depth: {width: 3\n").ok());
  Status s = OpenStatus();
  EXPECT_FALSE(s.ok());
  EXPECT_TRUE(Contains(s, dir_ + "/rig.yaml")) << s.message();
  // Valid YAML, invalid rig: the LoadRig message passes through.
  ASSERT_TRUE(WriteStringToFile(dir_ + "/rig.yaml", "name: x\npods: []\n").ok());
  s = OpenStatus();
  EXPECT_FALSE(s.ok());
  EXPECT_TRUE(Contains(s, dir_ + "/rig.yaml")) << s.message();
}

TEST_F(MalformedDataset, MissingFramesCsv) {
  std::filesystem::remove(dir_ + "/frames.csv");
  const Status s = OpenStatus();
  EXPECT_EQ(s.code(), StatusCode::kNotFound);
  EXPECT_TRUE(Contains(s, dir_ + "/frames.csv")) << s.message();
}

TEST_F(MalformedDataset, FramesCsvErrorsHaveLineNumbers) {
  const std::string csv = dir_ + "/frames.csv";
  struct Case {
    std::string text, expect;
  };
  const std::vector<Case> cases = {
      {"", csv + ": empty file"},
      {"frame;pod;timestamp_us\n", csv + ":1: expected header"},
      {"frame,pod,timestamp_us\n0,0,1\n0,1\n", csv + ":3: expected 3 fields"},
      {"frame,pod,timestamp_us\n0,0,1\n0,1,2,3\n", csv + ":3: expected 3 fields"},
      {"frame,pod,timestamp_us\n0,0,1\n0,x,2\n", csv + ":3: field 2 is not an integer"},
      {"frame,pod,timestamp_us\n0,0,1\n0,0,2\n", csv + ":3: duplicate row for frame 0 pod 0"},
      {"frame,pod,timestamp_us\n0,0,1\n0,2,2\n", csv + ":3: pod 2 is not in the rig"},
      {"frame,pod,timestamp_us\n1,0,1\n1,1,1\n0,0,1\n0,1,1\n", csv + ":4: frame 0 after frame 1"},
      {"frame,pod,timestamp_us\n0,0,1\n1,0,1\n1,1,1\n", csv + ":2: frame 0 has no row for pod 1"},
      {"frame,pod,timestamp_us\n-1,0,1\n", csv + ":2: frame must be >= 0"},
      {"frame,pod,timestamp_us\n0,0,99999999999999999999\n", csv + ":2: field 3 is not an integer"},
  };
  for (const auto& c : cases) {
    WriteCsv(c.text);
    const Status s = OpenStatus();
    EXPECT_EQ(s.code(), StatusCode::kDataLoss) << c.text;
    EXPECT_TRUE(Contains(s, c.expect)) << "got: " << s.message() << "\nexpected: " << c.expect;
  }
  // Windows line endings and a trailing blank line are fine.
  WriteCsv("frame,pod,timestamp_us\r\n0,1,5\r\n0,0,4\r\n\r\n");
  EXPECT_TRUE(OpenStatus().ok()) << OpenStatus().ToString();
}

TEST_F(MalformedDataset, EveryTruncationOfFramesCsvIsAnErrorOrAShorterDataset) {
  auto full = ReadFileToString(dir_ + "/frames.csv");
  ASSERT_TRUE(full.ok());
  for (size_t n = 0; n < full->size(); ++n) {
    WriteCsv(full->substr(0, n));
    auto r = DatasetReader::Open(dir_);
    if (!r.ok()) {
      EXPECT_TRUE(Contains(r.status(), dir_ + "/frames.csv")) << n << ": " << r.status().message();
      continue;
    }
    // Accepted prefixes end at a frame boundary (or inside the last timestamp's digits).
    EXPECT_LE((*r)->num_frames(), 3);
    RgbdFrameSet set;
    for (int64_t i = 0; i < (*r)->num_frames(); ++i) {
      ASSERT_TRUE((*r)->Read(i, &set).ok());
      EXPECT_EQ(set.frame_index, sets_[static_cast<size_t>(i)].frame_index);
    }
  }
}

TEST_F(MalformedDataset, MissingImage) {
  std::filesystem::remove(dir_ + "/pod1/depth/000001.png");
  EXPECT_TRUE(ReadStatus(0).ok());
  const Status s = ReadStatus(1);
  EXPECT_EQ(s.code(), StatusCode::kNotFound);
  EXPECT_TRUE(Contains(s, dir_ + "/pod1/depth/000001.png")) << s.message();
  std::filesystem::remove(dir_ + "/pod0/color/000005.png");
  const Status c = ReadStatus(2);
  EXPECT_TRUE(Contains(c, dir_ + "/pod0/color/000005.png")) << c.message();
}

TEST_F(MalformedDataset, WrongImageSize) {
  ASSERT_TRUE(WriteImageRgb8(dir_ + "/pod1/color/000000.png", ImageRgb8(41, 30)).ok());
  Status s = ReadStatus(0);
  EXPECT_EQ(s.code(), StatusCode::kDataLoss);
  EXPECT_EQ(s.message(), dir_ + "/pod1/color/000000.png: image is 41x30, rig.yaml pods[1].color says 40x30");
  ASSERT_TRUE(WriteDepth16(dir_ + "/pod0/depth/000001.png", ImageDepth16(40, 30)).ok());
  s = ReadStatus(1);
  EXPECT_TRUE(Contains(s, dir_ + "/pod0/depth/000001.png: image is 40x30, rig.yaml pods[0].depth says 32x24"))
      << s.message();
  ASSERT_TRUE(WriteMask8(dir_ + "/pod0/mask/000005.png", ImageGray8(8, 8)).ok());
  s = ReadStatus(2);
  EXPECT_TRUE(Contains(s, dir_ + "/pod0/mask/000005.png: image is 8x8")) << s.message();
}

TEST_F(MalformedDataset, EightBitDepth) {
  ASSERT_TRUE(WriteMask8(dir_ + "/pod1/depth/000000.png", ImageGray8(32, 24, 7)).ok());
  const Status s = ReadStatus(0);
  EXPECT_EQ(s.message(), dir_ + "/pod1/depth/000000.png: depth must be a 16-bit single-channel PNG, got 8-bit");
}

TEST_F(MalformedDataset, CorruptImageAndNextMovesOn) {
  ASSERT_TRUE(WriteStringToFile(dir_ + "/pod0/color/000001.png", "\x89PNG\r\n\x1a\n garbage").ok());
  auto r = DatasetReader::Open(dir_);
  ASSERT_TRUE(r.ok());
  RgbdFrameSet set;
  ASSERT_TRUE((*r)->Next(&set).ok());
  const Status s = (*r)->Next(&set);
  EXPECT_EQ(s.code(), StatusCode::kDataLoss);
  EXPECT_TRUE(Contains(s, dir_ + "/pod0/color/000001.png")) << s.message();
  // The damaged frame set is skipped by the next call.
  ASSERT_TRUE((*r)->Next(&set).ok());
  EXPECT_EQ(set.frame_index, 5);
}

TEST(Dataset, OpenRefusesNonDatasets) {
  auto r = DatasetReader::Open("/nonexistent/dataset/dir");
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.status().code(), StatusCode::kNotFound);
  const std::string empty = test::MakeTempDir("dataset_empty");
  auto e = DatasetReader::Open(empty);
  ASSERT_FALSE(e.ok());
  EXPECT_TRUE(Contains(e.status(), empty + "/rig.yaml"));
}

}  // namespace
}  // namespace holo
