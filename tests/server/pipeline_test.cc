// The pipeline scheduler with stand-in stages: order, completeness, equality
// with the serial run, error propagation, pacing.
#include <atomic>
#include <chrono>
#include <thread>

#include <gtest/gtest.h>

#include "server/pipeline/pipeline.h"

namespace holo {
namespace {

// Stand-in stages that leave a fingerprint of the frame in the mesh.
PipelineStages FakeStages(int64_t num_frames, std::vector<std::pair<int64_t, uint32_t>>* out) {
  PipelineStages st;
  st.acquire = [num_frames](FrameWork& w) -> Status {
    if (w.sequence >= num_frames) return OutOfRange("end");
    w.frames.frame_index = 1000 + w.sequence;
    w.frames.frames.resize(2);
    for (auto& f : w.frames.frames) f.depth.Resize(8, 8, static_cast<uint16_t>(w.sequence));
    return OkStatus();
  };
  st.segment = [](FrameWork& w) -> Status {
    for (auto& f : w.frames.frames) f.mask.Resize(8, 8, static_cast<uint8_t>(w.sequence * 7));
    // Vary timing so stages overlap in different ways.
    if (w.sequence % 5 == 0) std::this_thread::sleep_for(std::chrono::microseconds(300));
    return OkStatus();
  };
  st.fuse_mesh = [](FrameWork& w) -> Status {
    w.mesh.Clear();
    w.mesh.positions.assign(3, Eigen::Vector3f(static_cast<float>(w.frames.frames[0].depth.at(0, 0)), 0, 0));
    w.mesh.triangles.push_back({0, 1, 2});
    return OkStatus();
  };
  st.texture = [](FrameWork& w) -> Status {
    w.mesh.colors.assign(3, {static_cast<uint8_t>(w.frames.frames[1].mask.at(3, 3)), 1, 2});
    if (w.sequence % 7 == 0) std::this_thread::sleep_for(std::chrono::microseconds(500));
    return OkStatus();
  };
  st.sink = [out](const FrameWork& w) -> Status {
    const uint32_t fp = static_cast<uint32_t>(w.mesh.positions[0].x()) * 1000u + w.mesh.colors[0][0];
    out->push_back({w.frames.frame_index, fp});
    return OkStatus();
  };
  return st;
}

TEST(PipelineTest, ConcurrentRunKeepsOrderLosesNothingAndEqualsSerial) {
  std::vector<std::pair<int64_t, uint32_t>> serial, concurrent;
  PipelineOptions so;
  so.serial = true;
  auto s = Pipeline(FakeStages(100, &serial), so).Run();
  ASSERT_TRUE(s.ok()) << s.status().ToString();
  PipelineOptions co;
  co.queue_capacity = 2;
  auto c = Pipeline(FakeStages(100, &concurrent), co).Run();
  ASSERT_TRUE(c.ok()) << c.status().ToString();
  EXPECT_EQ(s->frames, 100);
  EXPECT_EQ(c->frames, 100);
  ASSERT_EQ(concurrent.size(), 100u);
  for (int64_t i = 0; i < 100; ++i) EXPECT_EQ(concurrent[static_cast<size_t>(i)].first, 1000 + i) << "order";
  EXPECT_EQ(serial, concurrent);
  EXPECT_EQ(c->per_frame.size(), 100u);
}

TEST(PipelineTest, KeepFrameTimingsBoundsPerFrameToTheNewest) {
  for (bool serial : {true, false}) {
    std::vector<std::pair<int64_t, uint32_t>> out;
    PipelineOptions o;
    o.serial = serial;
    o.keep_frame_timings = 10;
    auto r = Pipeline(FakeStages(95, &out), o).Run();
    ASSERT_TRUE(r.ok()) << r.status().ToString();
    EXPECT_EQ(r->frames, 95);
    EXPECT_EQ(out.size(), 95u);  // every frame still reaches the sink
    // 95 frames with keep 10: the oldest 10 go whenever 20 are held → frames 80..94.
    ASSERT_EQ(r->per_frame.size(), 15u) << "serial " << serial;
    for (size_t i = 1; i < r->per_frame.size(); ++i)
      EXPECT_GE(r->per_frame[i].acquired_us, r->per_frame[i - 1].acquired_us) << "order";
  }
  PipelineOptions bad;
  bad.keep_frame_timings = -1;
  EXPECT_FALSE(bad.Check().ok());
}

TEST(PipelineTest, MaxFramesStopsEarly) {
  std::vector<std::pair<int64_t, uint32_t>> out;
  PipelineOptions o;
  o.max_frames = 10;
  auto r = Pipeline(FakeStages(1000, &out), o).Run();
  ASSERT_TRUE(r.ok());
  EXPECT_EQ(r->frames, 10);
  EXPECT_EQ(out.size(), 10u);
}

TEST(PipelineTest, StageErrorStopsThePipelineAndIsReturned) {
  for (bool serial : {false, true}) {
    std::vector<std::pair<int64_t, uint32_t>> out;
    PipelineStages st = FakeStages(100, &out);
    st.fuse_mesh = [](FrameWork& w) -> Status {
      if (w.sequence == 17) return DataLoss("pod 3: depth image is 10x10, rig says 8x8");
      return OkStatus();
    };
    st.texture = nullptr;
    st.sink = [&out](const FrameWork& w) -> Status {
      out.push_back({w.sequence, 0});
      return OkStatus();
    };
    PipelineOptions o;
    o.serial = serial;
    auto r = Pipeline(st, o).Run();
    ASSERT_FALSE(r.ok());
    EXPECT_EQ(r.status().code(), StatusCode::kDataLoss);
    EXPECT_NE(r.status().message().find("pod 3"), std::string::npos);
    EXPECT_LE(out.size(), 17u) << "nothing after the failing frame is delivered";
  }
}

TEST(PipelineTest, PacedAcquireFollowsTheClock) {
  SimulatedClock clock(0);
  std::vector<std::pair<int64_t, uint32_t>> out;
  PipelineOptions o;
  o.serial = true;
  o.pace_fps = 30;
  auto r = Pipeline(FakeStages(31, &out), o, clock).Run();
  ASSERT_TRUE(r.ok());
  EXPECT_EQ(r->frames, 31);
  // Frame k is acquired at k periods of 33333 µs; the end of the source is
  // discovered at the slot of frame 31.
  EXPECT_EQ(clock.NowUs(), 31 * 33333);
  EXPECT_EQ(r->late_frames, 0);
  EXPECT_EQ(r->per_frame[30].acquired_us, 30 * 33333);
}

// A live site that cannot keep up skips camera frames instead of falling
// further and further behind: a fuse stage that takes 2.5 periods makes the
// serial pipeline take the frame of the slot current when it is ready again
// (slots 0, 2, 5, 7, 10, …), and latency stays one frame's work plus at
// most one period (a frame is stamped with its camera slot, which may have
// begun up to a period before the pipeline could take it).
TEST(PipelineTest, DropLateFramesSkipsToTheCurrentSlot) {
  SimulatedClock clock(0);
  std::vector<std::pair<int64_t, uint32_t>> out;
  PipelineOptions o;
  o.serial = true;
  o.pace_fps = 100;  // 10 ms slots
  o.drop_late_frames = true;
  o.max_frames = 30;
  PipelineStages st = FakeStages(1000, &out);
  st.fuse_mesh = [&clock, inner = st.fuse_mesh](FrameWork& w) {
    clock.AdvanceUs(25000);
    return inner(w);
  };
  auto r = Pipeline(st, o, clock).Run();
  ASSERT_TRUE(r.ok()) << r.status().ToString();
  ASSERT_GE(out.size(), 9u);
  EXPECT_EQ(r->frames + r->dropped_frames, 30) << "every slot is either taken or counted as dropped";
  EXPECT_GT(r->dropped_frames, 15);
  for (size_t i = 0; i < r->per_frame.size(); ++i) {
    EXPECT_LE(r->per_frame[i].latency_ms(), 25.0 + 10.0 + 1e-6) << "frame " << i;
    EXPECT_EQ(r->per_frame[i].acquired_us, (out[i].first - 1000) * 10000) << "stamped with its slot";
    if (i > 0) {
      const int64_t gap = out[i].first - out[i - 1].first;
      EXPECT_TRUE(gap == 2 || gap == 3) << "gap " << gap << " at frame " << i;
    }
  }

  // Without dropping every frame is taken and the lag grows.
  out.clear();
  SimulatedClock clock2(0);
  PipelineStages st2 = FakeStages(1000, &out);
  st2.fuse_mesh = [&clock2, inner = st2.fuse_mesh](FrameWork& w) {
    clock2.AdvanceUs(25000);
    return inner(w);
  };
  o.drop_late_frames = false;
  auto r2 = Pipeline(st2, o, clock2).Run();
  ASSERT_TRUE(r2.ok());
  EXPECT_EQ(r2->frames, 30);
  EXPECT_EQ(r2->dropped_frames, 0);
  EXPECT_GT(r2->late_frames, 20);
}

// The encode stage runs between texture and sink, in order, on its own
// thread, and what it leaves in the work item reaches the sink.
TEST(PipelineTest, EncodeStageFeedsTheSink) {
  std::vector<std::pair<int64_t, uint32_t>> out;
  for (bool serial : {true, false}) {
    out.clear();
    PipelineStages st = FakeStages(20, &out);
    st.encode = [](FrameWork& w) -> Status {
      if (!w.encoded) w.encoded = std::make_shared<int64_t>();
      *static_cast<int64_t*>(w.encoded.get()) = 5000 + w.frames.frame_index;
      return OkStatus();
    };
    std::vector<int64_t> encoded;
    st.sink = [&encoded](const FrameWork& w) -> Status {
      encoded.push_back(*static_cast<const int64_t*>(w.encoded.get()) - 5000);
      EXPECT_GE(w.timings.encoded_us, w.timings.ready_us);
      return OkStatus();
    };
    PipelineOptions o;
    o.serial = serial;
    o.max_in_flight = serial ? 0 : 3;
    auto r = Pipeline(st, o).Run();
    ASSERT_TRUE(r.ok());
    ASSERT_EQ(encoded.size(), 20u);
    for (size_t i = 0; i < encoded.size(); ++i) EXPECT_EQ(encoded[i], 1000 + static_cast<int64_t>(i));
  }
}

TEST(PipelineTest, AcquireErrorDeliversEarlierFramesThenFails) {
  std::vector<std::pair<int64_t, uint32_t>> out;
  PipelineStages st = FakeStages(100, &out);
  auto ok_acquire = st.acquire;
  st.acquire = [ok_acquire](FrameWork& w) -> Status {
    if (w.sequence == 5) return NotFound("pod1/depth/000005.png: no such file");
    return ok_acquire(w);
  };
  for (bool serial : {false, true}) {
    out.clear();
    PipelineOptions o;
    o.serial = serial;
    auto r = Pipeline(st, o).Run();
    ASSERT_FALSE(r.ok());
    EXPECT_NE(r.status().message().find("000005.png"), std::string::npos);
    EXPECT_EQ(out.size(), 5u) << "frames 0-4 were good and reach the sink (serial=" << serial << ")";
  }
}

TEST(PipelineTest, BadOptionsAreRejected) {
  std::vector<std::pair<int64_t, uint32_t>> out;
  PipelineOptions o;
  o.queue_capacity = 0;
  auto r = Pipeline(FakeStages(1, &out), o).Run();
  ASSERT_FALSE(r.ok());
  EXPECT_NE(r.status().message().find("queue_capacity"), std::string::npos);
  PipelineStages none;
  EXPECT_FALSE(Pipeline(none, PipelineOptions{}).Run().ok());
}

TEST(PipelineTest, MedianTimingsAndLatency) {
  PipelineStats stats;
  for (int i = 0; i < 5; ++i) {
    StageTimings t;
    t.segment_ms = i;
    t.acquired_us = 0;
    t.ready_us = 1000 * (i + 1);
    stats.per_frame.push_back(t);
  }
  EXPECT_EQ(MedianTimings(stats).segment_ms, 2.0);
  EXPECT_EQ(MedianLatencyMs(stats), 3.0);
}

}  // namespace
}  // namespace holo
