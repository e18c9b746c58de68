// The live packager and its part format (docs/broadcast.md): key frame at
// each segment start, parts in order and byte-identical to the segment, the
// manifest advancing, pruning, and no gap or reused name across a site restart
// or a packager restart; the part parser on every prefix and bit flip.
#include <filesystem>
#include <functional>
#include <map>
#include <set>

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include "common/file_util.h"
#include "record/record_test_util.h"
#include "protocol/live_format.h"
#include "server/record/live_packager.h"
#include "server/record/recording_reader.h"
#include "test_util.h"

namespace holo::record {
namespace {

using protocol::MessageType;

constexpr int64_t kBase = 1700000000000000;  // Unix µs of the first message

nlohmann::json Manifest(const std::string& dir) {
  auto text = ReadFileToString(dir + "/live.json");
  HOLO_CHECK_MSG(text.ok(), text.status().ToString());
  return nlohmann::json::parse(*text);
}

LivePackagerOptions Options(const std::string& dir) {
  LivePackagerOptions o;
  o.dir = dir;
  o.segment_us = 1000000;
  o.part_us = 250000;
  o.window_segments = 100;
  o.source = "test";
  return o;
}

// Feeds `msgs` as if received at base + time, ticking every 10 ms in between.
void Feed(LivePackager* p, const std::vector<test::TestMessage>& msgs, int64_t base,
          const std::function<void()>& after_each = {}) {
  int64_t tick = base;
  for (const auto& m : msgs) {
    while (tick + 10000 <= base + m.time_us) {
      tick += 10000;
      ASSERT_TRUE(p->Tick(tick).ok());
    }
    Status s = p->AddMessage(m.frame, base + m.time_us);
    ASSERT_TRUE(s.ok()) << s.ToString();
    if (after_each) after_each();
  }
}

// Checks every listed segment of `dir`: the first record is the Rig, the first
// MeshFrame is a key frame at the segment start, parts are consecutive and
// parse, and (complete ones) their concatenation is the segment file's records.
void CheckSegments(const std::string& dir) {
  const auto j = Manifest(dir);
  ASSERT_EQ(j["format"], "holoport-live");
  for (const auto& s : j["segments"]) {
    const uint64_t n = s["number"].get<uint64_t>();
    std::vector<uint8_t> joined;
    int64_t last_end = -1;
    for (size_t k = 0; k < s["parts"].size(); ++k) {
      const auto& pj = s["parts"][k];
      ASSERT_EQ(pj["name"], LivePartName(n, k));
      const auto bytes = test::ReadBytes(dir + "/" + pj["name"].get<std::string>());
      ASSERT_EQ(bytes.size(), pj["bytes"].get<uint64_t>());
      auto recs = ParseLiveRecords(bytes);
      ASSERT_TRUE(recs.ok()) << recs.status().ToString();
      ASSERT_EQ(recs->size(), pj["messages"].get<uint64_t>());
      EXPECT_EQ(recs->front().time_us, pj["start_us"].get<int64_t>());
      EXPECT_EQ(recs->back().time_us, pj["end_us"].get<int64_t>());
      EXPECT_GE(recs->front().time_us, last_end);  // parts in order
      last_end = recs->back().time_us;
      if (k == 0) {
        ASSERT_GE(recs->size(), 2u);
        EXPECT_EQ((*recs)[0].header.type, MessageType::kRig);
        EXPECT_EQ((*recs)[0].time_us, s["start_us"].get<int64_t>());
        // The first content after the Rig is a MeshFrame key frame at the start.
        size_t i = 1;
        while (i < recs->size() && (*recs)[i].header.type == MessageType::kRig) ++i;
        ASSERT_LT(i, recs->size());
        EXPECT_EQ((*recs)[i].header.type, MessageType::kMeshFrame);
        EXPECT_TRUE((*recs)[i].header.flags & protocol::kFlagKeyFrame);
        EXPECT_EQ((*recs)[i].time_us, s["start_us"].get<int64_t>());
      }
      joined.insert(joined.end(), bytes.begin(), bytes.end());
    }
    EXPECT_EQ(joined.size(), s["bytes"].get<uint64_t>());
    if (!s["complete"].get<bool>()) continue;
    ASSERT_EQ(s["file"], LiveSegmentFileName(n));
    const std::string path = dir + "/" + LiveSegmentFileName(n);
    auto r = RecordingReader::Open(path);
    ASSERT_TRUE(r.ok()) << r.status().ToString();
    EXPECT_TRUE((*r)->summary().clean);
    EXPECT_TRUE((*r)->summary().file.flags & kFileFlagSegment);
    const auto file = test::ReadBytes(path);
    ASSERT_EQ((*r)->summary().data_begin, kFileHeaderSize);
    const std::vector<uint8_t> records(file.begin() + static_cast<std::ptrdiff_t>((*r)->summary().data_begin),
                                       file.begin() + static_cast<std::ptrdiff_t>((*r)->summary().data_end));
    EXPECT_TRUE(records == joined) << "segment " << n << ": parts do not concatenate to the segment's records";
  }
}

TEST(LivePackager, SegmentsStartWithKeyFramesAndPartsConcatenateToThem) {
  const std::string dir = test::MakeTempDir("live_pack");
  const auto msgs = test::MakeTestStream(100);  // 3.3 s at 30 fps, audio interleaved
  auto p = LivePackager::Open(Options(dir), kBase);
  ASSERT_TRUE(p.ok()) << p.status().ToString();
  Feed(p->get(), msgs, kBase);
  ASSERT_TRUE((*p)->Finish(kBase + msgs.back().time_us + 1000).ok());
  const auto j = Manifest(dir);
  EXPECT_TRUE(j["ended"].get<bool>());
  EXPECT_EQ(j["availability_start_unix_us"].get<int64_t>(), kBase);
  ASSERT_EQ(j["segments"].size(), 4u);  // cuts at 1, 2, 3 s
  for (size_t i = 0; i < 4; ++i) {
    EXPECT_EQ(j["segments"][i]["number"].get<uint64_t>(), i);
    EXPECT_TRUE(j["segments"][i]["complete"].get<bool>());
    EXPECT_FALSE(j["segments"][i]["discontinuity"].get<bool>());
    EXPECT_EQ(j["segments"][i]["start_us"].get<int64_t>(), static_cast<int64_t>(i) * 1000000);
  }
  EXPECT_EQ(j["segments"][1]["parts"].size(), 4u);  // 1 s in 250 ms parts
  CheckSegments(dir);
  // Every message of the stream is in the parts once, in order (plus one
  // re-stamped Rig per segment after the first).
  uint64_t messages = 0;
  for (const auto& s : j["segments"])
    for (const auto& pj : s["parts"]) messages += pj["messages"].get<uint64_t>();
  EXPECT_EQ(messages, msgs.size() + 3);
  EXPECT_EQ((*p)->stats().dropped_before_key, 0u);
  // No temporary file is left behind.
  for (const auto& e : std::filesystem::directory_iterator(dir))
    EXPECT_NE(e.path().filename().string()[0], '.') << e.path();
}

TEST(LivePackager, ManifestAdvancesAfterEveryPartAndOnlyGrowsAtItsEnd) {
  const std::string dir = test::MakeTempDir("live_adv");
  const auto msgs = test::MakeTestStream(75);
  auto p = LivePackager::Open(Options(dir), kBase);
  ASSERT_TRUE(p.ok());
  std::vector<std::string> seen;  // every part name listed, in listing order
  int64_t last_published = 0;
  int manifests = 0;
  Feed(p->get(), msgs, kBase, [&] {
    if (!FileExists(dir + "/live.json")) return;
    const auto j = Manifest(dir);
    const int64_t published = j["published_unix_us"].get<int64_t>();
    ASSERT_GE(published, last_published);
    if (published == last_published) return;
    last_published = published;
    ++manifests;
    std::vector<std::string> names;
    for (const auto& s : j["segments"])
      for (const auto& pj : s["parts"]) {
        names.push_back(pj["name"]);
        // A listed part exists and is complete.
        ASSERT_EQ(std::filesystem::file_size(dir + "/" + names.back()), pj["bytes"].get<uint64_t>());
      }
    // The new listing extends the old one.
    ASSERT_GE(names.size(), seen.size());
    for (size_t i = 0; i < seen.size(); ++i) ASSERT_EQ(names[i], seen[i]);
    seen = names;
  });
  EXPECT_GE(manifests, 8);       // ≥ one per part over 2.5 s
  EXPECT_GE(seen.size(), 8u);
  // Tick alone publishes a due part (no message needed).
  const auto before = Manifest(dir)["published_unix_us"].get<int64_t>();
  ASSERT_TRUE((*p)->Tick(kBase + msgs.back().time_us + 300000).ok());
  EXPECT_GT(Manifest(dir)["published_unix_us"].get<int64_t>(), before);
}

TEST(LivePackager, SiteRestartIsADiscontinuityWithoutGapOrReusedName) {
  const std::string dir = test::MakeTempDir("live_restart");
  const auto msgs = test::MakeTestStream(45);  // 1.5 s
  auto p = LivePackager::Open(Options(dir), kBase);
  ASSERT_TRUE(p.ok());
  Feed(p->get(), msgs, kBase);
  const int64_t cut = kBase + msgs.back().time_us + 10000;
  ASSERT_TRUE((*p)->Discontinuity(cut).ok());
  // Content without a new Rig is dropped until the Rig and a key frame come.
  Status s = (*p)->AddMessage(msgs[1].frame, cut + 1000);
  ASSERT_TRUE(s.ok());
  EXPECT_GE((*p)->stats().dropped_before_key, 1u);
  // The restarted site's stream (its own frame numbers from 0) 0.5 s later.
  Feed(p->get(), msgs, cut + 500000);
  ASSERT_TRUE((*p)->Finish(cut + 500000 + msgs.back().time_us + 1000).ok());
  const auto j = Manifest(dir);
  ASSERT_EQ(j["segments"].size(), 4u);
  std::vector<uint64_t> numbers;
  for (const auto& seg : j["segments"]) numbers.push_back(seg["number"].get<uint64_t>());
  EXPECT_EQ(numbers, (std::vector<uint64_t>{0, 1, 2, 3}));  // no gap
  EXPECT_FALSE(j["segments"][1]["discontinuity"].get<bool>());
  EXPECT_TRUE(j["segments"][2]["discontinuity"].get<bool>());
  EXPECT_FALSE(j["segments"][3]["discontinuity"].get<bool>());
  // Broadcast time keeps going forward through the restart.
  EXPECT_GT(j["segments"][2]["start_us"].get<int64_t>(), j["segments"][1]["end_us"].get<int64_t>());
  CheckSegments(dir);
}

TEST(LivePackager, PackagerRestartContinuesNumberingAndKeepsTheTimeline) {
  const std::string dir = test::MakeTempDir("live_reopen");
  const auto msgs = test::MakeTestStream(75);
  std::map<std::string, std::vector<uint8_t>> before;
  int64_t end_time = 0;
  {
    auto p = LivePackager::Open(Options(dir), kBase);
    ASSERT_TRUE(p.ok());
    Feed(p->get(), msgs, kBase);
    // Killed without Finish: segment 2 is open (its parts exist, its .hrec does not).
    end_time = kBase + msgs.back().time_us;
  }
  for (const auto& e : std::filesystem::directory_iterator(dir))
    before[e.path().filename().string()] = test::ReadBytes(e.path().string());
  const int64_t later = end_time + 3000000;
  auto p = LivePackager::Open(Options(dir), later);
  ASSERT_TRUE(p.ok()) << p.status().ToString();
  EXPECT_EQ((*p)->availability_start_unix_us(), kBase);
  EXPECT_EQ((*p)->next_segment(), 3u);
  Feed(p->get(), msgs, later);
  ASSERT_TRUE((*p)->Finish(later + msgs.back().time_us + 1000).ok());
  const auto j = Manifest(dir);
  std::vector<uint64_t> numbers;
  for (const auto& seg : j["segments"]) numbers.push_back(seg["number"].get<uint64_t>());
  // 0 and 1 complete from the first run, 2 (never closed) not listed again,
  // then 3.. from this run, the first a discontinuity.
  ASSERT_GE(numbers.size(), 4u);
  EXPECT_EQ(numbers[0], 0u);
  EXPECT_EQ(numbers[1], 1u);
  EXPECT_EQ(numbers[2], 3u);
  EXPECT_TRUE(j["segments"][2]["discontinuity"].get<bool>());
  EXPECT_EQ(j["segments"][2]["start_us"].get<int64_t>(), later - kBase);
  // No file of the first run was rewritten.
  for (const auto& [name, bytes] : before) {
    if (name == "live.json" || name[0] == '.') continue;
    EXPECT_EQ(test::ReadBytes(dir + "/" + name), bytes) << name << " was rewritten";
  }
  CheckSegments(dir);
}

TEST(LivePackager, OldSegmentsLeaveTheListThenTheDisk) {
  const std::string dir = test::MakeTempDir("live_prune");
  LivePackagerOptions o = Options(dir);
  o.window_segments = 2;
  o.keep_extra_segments = 1;
  auto p = LivePackager::Open(o, kBase);
  ASSERT_TRUE(p.ok());
  const auto msgs = test::MakeTestStream(180);  // 6 s: segments 0..5
  Feed(p->get(), msgs, kBase);
  ASSERT_TRUE((*p)->Finish(kBase + msgs.back().time_us + 1000).ok());
  const auto j = Manifest(dir);
  ASSERT_EQ(j["segments"].size(), 2u);
  EXPECT_EQ(j["segments"][0]["number"].get<uint64_t>(), 4u);
  EXPECT_EQ(j["segments"][1]["number"].get<uint64_t>(), 5u);
  std::set<uint64_t> on_disk;
  for (const auto& e : std::filesystem::directory_iterator(dir)) {
    const std::string name = e.path().filename().string();
    if (name.rfind("seg_", 0) == 0) on_disk.insert(std::stoull(name.substr(4, 5)));
  }
  EXPECT_EQ(on_disk, (std::set<uint64_t>{3, 4, 5}));  // the window + 1 kept
  CheckSegments(dir);
}

// A site with inter-frame colour (V1): a whole-frame key frame only every
// `interval` frames, or on the frame after a request (Control
// kRequestKeyFrame). Returns the segments' start times.
std::vector<int64_t> PackageInterFrameSite(const std::string& dir, bool ask, int interval, uint64_t* requests) {
  auto msgs = test::MakeTestStream(300);  // 10 s at 30 fps
  auto p = LivePackager::Open(Options(dir), kBase);
  HOLO_CHECK_MSG(p.ok(), p.status().ToString());
  bool requested = false;
  int frame = 0;
  int64_t tick = kBase;
  for (auto& m : msgs) {
    while (tick + 10000 <= kBase + m.time_us) {
      tick += 10000;
      HOLO_CHECK((*p)->Tick(tick).ok());
      if ((*p)->WantsKeyFrame(tick) && ask) requested = true;
    }
    if (m.type == protocol::MessageType::kMeshFrame) {
      auto h = protocol::DecodeHeader(m.frame.data(), m.frame.size());
      HOLO_CHECK(h.ok());
      const bool key = frame % interval == 0 || requested;
      requested = requested && !key;
      h->flags = key ? protocol::kFlagKeyFrame : 0;
      protocol::EncodeHeader(*h, m.frame.data());
      ++frame;
    }
    HOLO_CHECK((*p)->AddMessage(m.frame, kBase + m.time_us).ok());
  }
  HOLO_CHECK((*p)->Finish(kBase + msgs.back().time_us + 1000).ok());
  *requests = (*p)->stats().keyframe_requests;
  std::vector<int64_t> starts;
  const auto manifest = Manifest(dir);
  for (const auto& seg : manifest["segments"]) starts.push_back(seg["start_us"].get<int64_t>());
  return starts;
}

TEST(LivePackager, AsksAnInterFrameSiteForKeyFramesSoSegmentsKeepTheirLength) {
  // Without asking, segments can only cut at the site's own key frames
  // (every 2 s here): twice the 1 s target.
  uint64_t requests = 0;
  const std::string quiet = test::MakeTempDir("live_v1_quiet");
  const auto plain = PackageInterFrameSite(quiet, /*ask=*/false, 60, &requests);
  ASSERT_EQ(plain.size(), 5u);
  for (size_t i = 1; i < plain.size(); ++i) EXPECT_EQ(plain[i] - plain[i - 1], 2000000);
  CheckSegments(quiet);
  // Asking when a segment is due: every segment within two frames of its
  // target, each starting at a key frame.
  const std::string asked = test::MakeTempDir("live_v1_asked");
  const auto starts = PackageInterFrameSite(asked, /*ask=*/true, 60, &requests);
  ASSERT_GE(starts.size(), 9u);
  for (size_t i = 1; i < starts.size(); ++i) {
    EXPECT_GE(starts[i] - starts[i - 1], 1000000) << "segment " << i;
    EXPECT_LE(starts[i] - starts[i - 1], 1000000 + 2 * 33334) << "segment " << i;
  }
  CheckSegments(asked);
  // One request per segment boundary, not one per tick (at most one per
  // part length while a key frame is awaited).
  EXPECT_GE(requests, starts.size() - 1);
  EXPECT_LE(requests, 2 * starts.size() + 2);
}

TEST(LivePackager, RefusesBadOptionsAndABadManifest) {
  const std::string dir = test::MakeTempDir("live_bad");
  LivePackagerOptions o = Options(dir);
  o.part_us = o.segment_us + 1;
  EXPECT_EQ(LivePackager::Open(o, kBase).status().code(), StatusCode::kInvalidArgument);
  o = Options(dir);
  o.cache_bucket_ms = -1;
  EXPECT_EQ(LivePackager::Open(o, kBase).status().code(), StatusCode::kInvalidArgument);
  ASSERT_TRUE(WriteStringToFile(dir + "/live.json", "{\"format\": \"something else\"}").ok());
  auto p = LivePackager::Open(Options(dir), kBase);
  ASSERT_FALSE(p.ok());
  EXPECT_EQ(p.status().code(), StatusCode::kDataLoss);
  EXPECT_NE(p.status().message().find("format"), std::string::npos) << p.status().message();
}

TEST(LivePackager, InvalidMessagesAreRejectedAndTheBroadcastGoesOn) {
  const std::string dir = test::MakeTempDir("live_inval");
  const auto msgs = test::MakeTestStream(40);
  auto p = LivePackager::Open(Options(dir), kBase);
  ASSERT_TRUE(p.ok());
  Feed(p->get(), std::vector<test::TestMessage>(msgs.begin(), msgs.begin() + 20), kBase);
  std::vector<uint8_t> bad = msgs[5].frame;
  bad[bad.size() / 2] ^= 0xFF;  // inside the payload
  bad.resize(bad.size() - 3);   // and the length no longer matches
  EXPECT_EQ((*p)->AddMessage(bad, kBase + msgs[19].time_us).code(), StatusCode::kInvalidArgument);
  Feed(p->get(), std::vector<test::TestMessage>(msgs.begin() + 20, msgs.end()), kBase);
  ASSERT_TRUE((*p)->Finish(kBase + 2000000).ok());
  EXPECT_EQ((*p)->stats().rejected, 1u);
  CheckSegments(dir);
}

// The part parser on untrusted bytes: every prefix (each in a fresh buffer)
// and every single-bit flip of a real part either parses to a prefix of its
// records or fails with DataLoss; never reads outside the input.
TEST(LivePart, EveryPrefixAndBitFlipIsRejectedOrConsistent) {
  const std::string dir = test::MakeTempDir("live_part");
  const auto msgs = test::MakeTestStream(12, 30, 2);
  auto p = LivePackager::Open(Options(dir), kBase);
  ASSERT_TRUE(p.ok());
  Feed(p->get(), msgs, kBase);
  ASSERT_TRUE((*p)->Finish(kBase + 500000).ok());
  const auto part = test::ReadBytes(dir + "/" + LivePartName(0, 0));
  auto full = ParseLiveRecords(part);
  ASSERT_TRUE(full.ok()) << full.status().ToString();
  ASSERT_GE(full->size(), 3u);
  for (size_t n = 0; n < part.size(); ++n) {
    std::vector<uint8_t> prefix(part.begin(), part.begin() + static_cast<std::ptrdiff_t>(n));
    auto r = ParseLiveRecords(prefix);
    // A prefix ending exactly at a record end is a valid, shorter part.
    if (r.ok()) {
      ASSERT_LT(r->size(), full->size());
      ASSERT_GT(n, 0u);
    } else {
      ASSERT_EQ(r.status().code(), StatusCode::kDataLoss) << n;
    }
  }
  for (size_t bit = 0; bit < part.size() * 8; bit += 7) {
    std::vector<uint8_t> flipped = part;
    flipped[bit / 8] ^= static_cast<uint8_t>(1u << (bit % 8));
    auto r = ParseLiveRecords(flipped);
    // Every byte is covered by a CRC or a checked field, so a flip never passes.
    EXPECT_FALSE(r.ok()) << "bit " << bit;
  }
}

}  // namespace
}  // namespace holo::record
