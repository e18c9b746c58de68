// Segments for an HTTP cache, the --info inspection, and the synthetic
// protocol stream that holoport-record writes.
#include <filesystem>

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include "common/clock.h"
#include "common/file_util.h"
#include "record/record_test_util.h"
#include "server/record/inspect.h"
#include "server/record/recording_reader.h"
#include "server/record/replay.h"
#include "server/record/replay_command.h"
#include "server/record/segments.h"
#include "server/record/synthetic_stream.h"
#include "test_util.h"

namespace holo::record {
namespace {

using protocol::MessageType;

std::vector<RecordedMessage> ReadAll(const RecordingReader& r) {
  std::vector<RecordedMessage> out;
  for (uint64_t at = r.summary().data_begin; at < r.summary().data_end;) {
    auto m = r.ReadAt(at);
    HOLO_CHECK_MSG(m.ok(), m.status().ToString());
    at = m->next_offset;
    out.push_back(std::move(*m));
  }
  return out;
}

TEST(RecordSegments, EverySegmentPlaysAloneAndTogetherTheyAreTheRecording) {
  const std::string dir = test::MakeTempDir("record_seg");
  const auto msgs = test::MakeTestStream(100);  // 3.3 s
  test::WriteTestRecording(dir + "/r.hrec", msgs);
  auto r = RecordingReader::Open(dir + "/r.hrec");
  ASSERT_TRUE(r.ok());
  auto segs = CutSegments(**r, 1000000, dir + "/segs");
  ASSERT_TRUE(segs.ok()) << segs.status().ToString();
  ASSERT_EQ(segs->size(), 4u);
  auto manifest = ReadFileToString(dir + "/segs/manifest.json");
  ASSERT_TRUE(manifest.ok());
  const auto j = nlohmann::json::parse(*manifest);
  ASSERT_EQ(j["segments"].size(), 4u);

  std::vector<std::vector<uint8_t>> joined;
  for (size_t i = 0; i < segs->size(); ++i) {
    const SegmentInfo& s = (*segs)[i];
    EXPECT_EQ(j["segments"][i]["file"], s.file);
    EXPECT_EQ(s.start_us, i == 0 ? 0 : static_cast<int64_t>(i) * 1000000);  // key frames fall on whole seconds
    auto seg = RecordingReader::Open(dir + "/segs/" + s.file);
    ASSERT_TRUE(seg.ok()) << seg.status().ToString();
    EXPECT_TRUE((*seg)->summary().clean);
    EXPECT_TRUE((*seg)->summary().file.flags & kFileFlagSegment);
    const auto got = ReadAll(**seg);
    ASSERT_GE(got.size(), 2u);
    EXPECT_EQ(got[0].header.type, MessageType::kRig);
    EXPECT_EQ(got[0].time_us, s.start_us);
    EXPECT_EQ(got[1].header.type, MessageType::kMeshFrame);
    EXPECT_TRUE(got[1].header.flags & protocol::kFlagKeyFrame);
    for (size_t k = (i == 0 ? 0 : 1); k < got.size(); ++k) joined.push_back(*got[k].bytes);
    // A segment replays alone from its first key frame, without waiting for its start time.
    SimulatedClock clock(5000000);
    auto src = ReplaySource::Create(std::shared_ptr<const RecordingReader>(std::move(*seg)), &clock);
    ASSERT_TRUE(src.ok()) << src.status().ToString();
    std::vector<protocol::Header> out;
    auto n = (*src)->Pump([&](std::shared_ptr<const std::vector<uint8_t>>, protocol::Header h) { out.push_back(h); });
    ASSERT_TRUE(n.ok());
    ASSERT_GE(out.size(), 2u);
    EXPECT_EQ(out[1].type, MessageType::kMeshFrame);
    EXPECT_EQ(out[1].capture_time_us, s.start_us);
  }
  // Segments together: the recording's messages, byte-identical, in order.
  ASSERT_EQ(joined.size(), msgs.size());
  for (size_t i = 0; i < msgs.size(); ++i) EXPECT_EQ(joined[i], msgs[i].frame) << i;
  EXPECT_FALSE(CutSegments(**r, 1000, dir + "/x").ok());
}

TEST(RecordInspect, CountsAndValidates) {
  const std::string dir = test::MakeTempDir("record_inspect");
  const auto msgs = test::MakeTestStream(30);
  test::WriteTestRecording(dir + "/r.hrec", msgs);
  auto r = RecordingReader::Open(dir + "/r.hrec");
  ASSERT_TRUE(r.ok());
  auto in = InspectRecording(**r, /*deep=*/true);
  ASSERT_TRUE(in.ok()) << in.status().ToString();
  EXPECT_EQ(in->messages, msgs.size());
  EXPECT_EQ(in->mesh_frames, 30u);
  EXPECT_EQ(in->key_frames, 30u);
  EXPECT_EQ(in->decoded_meshes, 30u);
  EXPECT_EQ(in->rigs, 1u);
  EXPECT_EQ(in->first_frame_index, 0);
  EXPECT_EQ(in->last_frame_index, 29);
  EXPECT_LE(in->max_key_gap_us, 33334);
  const std::string text = InspectionText(**r, *in);
  EXPECT_NE(text.find("30 key frames"), std::string::npos) << text;
  const auto j = nlohmann::json::parse(InspectionJson(**r, *in));
  EXPECT_EQ(j["mesh_frames"], 30);
  EXPECT_EQ(j["valid"], true);
}

TEST(RecordSyntheticStream, IsAValidTimeOrderedProtocolStream) {
  SyntheticStreamOptions o;
  auto s = SyntheticStream::Create(o);
  ASSERT_TRUE(s.ok()) << s.status().ToString();
  StreamMessage m;
  int64_t last = -1;
  int meshes = 0, audio = 0;
  for (int i = 0; i < 30; ++i) {
    ASSERT_TRUE((*s)->Next(&m).ok());
    if (i == 0) {
      EXPECT_EQ(m.type, MessageType::kRig);
    }
    EXPECT_GE(m.time_us, last);
    last = m.time_us;
    auto dec = protocol::DecodeMessage(m.frame);
    ASSERT_TRUE(dec.ok()) << dec.status().ToString();
    if (m.type == MessageType::kMeshFrame) {
      ++meshes;
      EXPECT_TRUE(dec->header.flags & protocol::kFlagKeyFrame);
      Mesh mesh;
      ASSERT_TRUE(protocol::DecodeGeometry(std::get<protocol::MeshFrame>(dec->payload).data, &mesh).ok());
      EXPECT_GT(mesh.num_triangles(), 1000u);
    }
    if (m.type == MessageType::kAudioPose) ++audio;
  }
  EXPECT_GT(meshes, 8);
  EXPECT_GT(audio, 14);
  o.workload = "nope";
  EXPECT_FALSE(SyntheticStream::Create(o).ok());
}

TEST(RecordReplayCommand, ReplaysAFileAndExportsEveryMeshFrame) {
  const std::string dir = test::MakeTempDir("record_cmd");
  test::WriteTestRecording(dir + "/r.hrec", test::MakeTestStream(12));
  ReplayCommandOptions o;
  o.path = dir + "/r.hrec";
  o.speed = 4;
  o.export_dir = dir + "/out";
  o.stats_path = dir + "/stats.jsonl";
  o.quiet = true;
  ASSERT_EQ(RunReplayCommand(o), 0);
  size_t plys = 0;
  for (const auto& e : std::filesystem::directory_iterator(dir + "/out")) plys += e.path().extension() == ".ply";
  EXPECT_EQ(plys, 12u);
  auto stats = ReadFileToString(dir + "/stats.jsonl");
  ASSERT_TRUE(stats.ok());
  EXPECT_EQ(std::count(stats->begin(), stats->end(), '\n'), static_cast<long>(test::MakeTestStream(12).size()));
  o.speed = 5;
  EXPECT_EQ(RunReplayCommand(o), 1);
  o.speed = 1;
  o.path = dir + "/missing.hrec";
  EXPECT_EQ(RunReplayCommand(o), 1);
}

}  // namespace
}  // namespace holo::record
