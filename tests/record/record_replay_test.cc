// The replay engine in simulated time: pacing, speed, pause, seek (± one
// frame), loop, the Control API, push mode, damage found while replaying.
#include <algorithm>
#include <cmath>
#include <limits>
#include <random>
#include <thread>

#include <gtest/gtest.h>

#include "common/clock.h"
#include "record/record_test_util.h"
#include "server/record/recording_reader.h"
#include "server/record/replay.h"
#include "test_util.h"

namespace holo::record {
namespace {

using protocol::MessageType;

struct Emitted {
  int64_t clock_us;
  protocol::Header header;
  std::shared_ptr<const std::vector<uint8_t>> bytes;
};

class ReplayTest : public ::testing::Test {
 protected:
  void Make(int frames, double fps = 30) {
    dir_ = test::MakeTempDir("record_replay");
    msgs_ = test::MakeTestStream(frames, fps);
    test::WriteTestRecording(dir_ + "/r.hrec", msgs_);
    auto r = RecordingReader::Open(dir_ + "/r.hrec");
    ASSERT_TRUE(r.ok()) << r.status().ToString();
    reader_ = std::shared_ptr<const RecordingReader>(std::move(*r));
  }
  std::unique_ptr<ReplaySource> Source(ReplayOptions o = {}) {
    auto s = ReplaySource::Create(reader_, &clock_, o);
    HOLO_CHECK_MSG(s.ok(), s.status().ToString());
    return std::move(*s);
  }
  // Advances simulated time in `step_us` steps until `until_us`, pumping.
  void RunUntil(ReplaySource& src, int64_t until_us, int64_t step_us = 1000) {
    while (clock_.NowUs() < until_us) {
      Pump(src);
      clock_.AdvanceUs(step_us);
    }
    Pump(src);
  }
  void Pump(ReplaySource& src) {
    auto n = src.Pump([&](std::shared_ptr<const std::vector<uint8_t>> b, protocol::Header h) {
      out_.push_back({clock_.NowUs(), h, std::move(b)});
    });
    ASSERT_TRUE(n.ok()) << n.status().ToString();
  }
  std::vector<Emitted> Meshes() const {
    std::vector<Emitted> v;
    for (const auto& e : out_)
      if (e.header.type == MessageType::kMeshFrame) v.push_back(e);
    return v;
  }

  std::string dir_;
  std::vector<test::TestMessage> msgs_;
  std::shared_ptr<const RecordingReader> reader_;
  SimulatedClock clock_{1000000};
  std::vector<Emitted> out_;
};

TEST_F(ReplayTest, OriginalPacingByteIdentical) {
  Make(60);
  auto src = Source();
  const int64_t start = clock_.NowUs();
  RunUntil(*src, start + 2100000);
  ASSERT_EQ(out_.size(), msgs_.size());
  for (size_t i = 0; i < out_.size(); ++i) {
    EXPECT_EQ(*out_[i].bytes, msgs_[i].frame) << i;
    // Emitted within one 1 ms pump step of its recorded time.
    EXPECT_GE(out_[i].clock_us - start, msgs_[i].time_us) << i;
    EXPECT_LE(out_[i].clock_us - start, msgs_[i].time_us + 1000) << i;
  }
  EXPECT_TRUE(src->state().ended);
  EXPECT_EQ(src->NextDueUs(), std::numeric_limits<int64_t>::max());
}

TEST_F(ReplayTest, SpeedScalesPacingAndIsValidated) {
  Make(30);
  for (double speed : {0.25, 0.5, 2.0, 4.0}) {
    out_.clear();
    ReplayOptions o;
    o.speed = speed;
    auto src = Source(o);
    const int64_t start = clock_.NowUs();
    RunUntil(*src, start + static_cast<int64_t>(1.1e6 / speed) + 10000, 500);
    ASSERT_EQ(out_.size(), msgs_.size()) << speed;
    for (size_t i = 0; i < out_.size(); ++i) {
      const double want = static_cast<double>(msgs_[i].time_us) / speed;
      EXPECT_NEAR(static_cast<double>(out_[i].clock_us - start), want, 501) << speed << " " << i;
    }
  }
  auto src = Source();
  for (double bad : {0.2, 4.01, 0.0, -1.0, std::nan(""), 8.0})
    EXPECT_EQ(src->SetSpeed(bad).code(), StatusCode::kInvalidArgument) << bad;
  ReplayOptions o;
  o.speed = 5;
  EXPECT_FALSE(ReplaySource::Create(reader_, &clock_, o).ok());
  // Changing speed mid-way keeps the position.
  const int64_t start = clock_.NowUs();
  RunUntil(*src, start + 300000);
  ASSERT_TRUE(src->SetSpeed(2.0).ok());
  EXPECT_NEAR(static_cast<double>(src->state().position_us), 300000, 1);
  clock_.AdvanceUs(100000);
  EXPECT_NEAR(static_cast<double>(src->state().position_us), 500000, 1);
}

TEST_F(ReplayTest, PauseFreezesAndResumeContinues) {
  Make(60);
  auto src = Source();
  const int64_t start = clock_.NowUs();
  RunUntil(*src, start + 500000);
  src->Pause();
  const size_t before = out_.size();
  EXPECT_EQ(src->NextDueUs(), std::numeric_limits<int64_t>::max());
  RunUntil(*src, start + 1500000);
  EXPECT_EQ(out_.size(), before);
  EXPECT_TRUE(src->state().paused);
  EXPECT_NEAR(static_cast<double>(src->state().position_us), 500000, 1000);
  src->Resume();
  RunUntil(*src, start + 3100000);
  ASSERT_EQ(out_.size(), msgs_.size());
  // After the pause every message is one second late, nothing lost or repeated.
  for (size_t i = before; i < out_.size(); ++i) {
    EXPECT_EQ(*out_[i].bytes, msgs_[i].frame);
    EXPECT_NEAR(static_cast<double>(out_[i].clock_us - start - 1000000), static_cast<double>(msgs_[i].time_us), 1001);
  }
}

TEST_F(ReplayTest, SeekLandsWithinOneFrame) {
  Make(90);
  const int64_t frame_us = 33334;
  std::mt19937 rng(7);
  std::uniform_int_distribution<int64_t> pick(0, reader_->summary().duration_us);
  auto src = Source();
  for (int trial = 0; trial < 200; ++trial) {
    const int64_t t = trial < 4 ? std::vector<int64_t>{0, 1, reader_->summary().duration_us, 1000000}[trial]
                                : pick(rng);
    out_.clear();
    ASSERT_TRUE(src->Seek(t).ok()) << t;
    const int64_t at = clock_.NowUs();
    Pump(*src);
    ASSERT_FALSE(out_.empty());
    // The Rig comes first, then the key frame at or just before t.
    EXPECT_EQ(out_[0].header.type, MessageType::kRig);
    const auto meshes = Meshes();
    ASSERT_EQ(meshes.size(), 1u) << t;
    const int64_t shown = meshes[0].header.capture_time_us;
    EXPECT_LE(shown, t);
    EXPECT_GT(shown, t - frame_us) << "seek to " << t;
    EXPECT_EQ(meshes[0].clock_us, at);
    // No audio from before the target is replayed.
    for (const auto& e : out_)
      if (e.header.type == MessageType::kAudioPose) {
        EXPECT_GE(e.header.capture_time_us, t);
      }
    EXPECT_NEAR(static_cast<double>(src->state().position_us), static_cast<double>(t), 1);
    // The next frame comes at its own time relative to t.
    if (t + frame_us < reader_->summary().duration_us) {
      out_.clear();
      RunUntil(*src, at + frame_us + 1000, 500);
      const auto next = Meshes();
      ASSERT_GE(next.size(), 1u);
      EXPECT_NEAR(static_cast<double>(next[0].clock_us - at),
                  static_cast<double>(next[0].header.capture_time_us - t), 501);
    }
  }
  EXPECT_EQ(src->Seek(-1).code(), StatusCode::kOutOfRange);
  EXPECT_EQ(src->Seek(reader_->summary().duration_us + 1).code(), StatusCode::kOutOfRange);
  EXPECT_GE(src->state().generation, 200u);
}

TEST_F(ReplayTest, SeekWhilePausedShowsTheFrameAndStaysPaused) {
  Make(60);
  auto src = Source();
  src->Pause();
  ASSERT_TRUE(src->Seek(1234567).ok());
  RunUntil(*src, clock_.NowUs() + 500000);
  const auto meshes = Meshes();
  ASSERT_EQ(meshes.size(), 1u);
  EXPECT_EQ(meshes[0].header.capture_time_us, 1233333);
  EXPECT_TRUE(src->state().paused);
  EXPECT_EQ(src->state().position_us, 1234567);
}

TEST_F(ReplayTest, LoopsForever) {
  Make(10);
  ReplayOptions o;
  o.loop = true;
  auto src = Source(o);
  const int64_t start = clock_.NowUs();
  // 10 frames at 30 fps + one frame gap = 333 ms per lap; 3 laps.
  RunUntil(*src, start + 3 * 333333 - 2000);
  const auto meshes = Meshes();
  ASSERT_EQ(meshes.size(), 30u);
  for (size_t i = 0; i < meshes.size(); ++i) {
    EXPECT_EQ(meshes[i].header.sequence, i % 10) << i;
    // Evenly paced across the wrap.
    EXPECT_NEAR(static_cast<double>(meshes[i].clock_us - start), static_cast<double>(i) * 33333.3, 1001) << i;
  }
  EXPECT_FALSE(src->state().ended);
  EXPECT_EQ(src->state().generation, 2u);
  // Each lap starts with the Rig.
  size_t rigs = 0;
  for (const auto& e : out_) rigs += e.header.type == MessageType::kRig;
  EXPECT_EQ(rigs, 3u);
  // Turning loop off lets it end; turning it on after the end restarts it.
  src->SetLoop(false);
  RunUntil(*src, clock_.NowUs() + 400000);
  EXPECT_TRUE(src->state().ended);
  src->SetLoop(true);
  out_.clear();
  RunUntil(*src, clock_.NowUs() + 50000);
  EXPECT_FALSE(out_.empty());
  // A caller that stops pumping for 100 s gets one lap, not 300 missed ones.
  clock_.AdvanceUs(100000000);
  out_.clear();
  Pump(*src);
  EXPECT_LE(out_.size(), 2 * msgs_.size());
}

TEST_F(ReplayTest, ControlMessagesDriveIt) {
  Make(60);
  auto src = Source();
  protocol::Control c;
  c.command = protocol::ControlCommand::kPause;
  ASSERT_TRUE(src->ApplyControl(c).ok());
  EXPECT_TRUE(src->state().paused);
  c.command = protocol::ControlCommand::kSeek;
  c.value = 1000000;
  ASSERT_TRUE(src->ApplyControl(c).ok());
  EXPECT_EQ(src->state().position_us, 1000000);
  c.command = protocol::ControlCommand::kSetSpeed;
  c.speed = 2.0f;
  ASSERT_TRUE(src->ApplyControl(c).ok());
  EXPECT_EQ(src->state().speed, 2.0);
  c.speed = 8.0f;  // valid on the wire, not for replay
  EXPECT_EQ(src->ApplyControl(c).code(), StatusCode::kInvalidArgument);
  c.command = protocol::ControlCommand::kResume;
  ASSERT_TRUE(src->ApplyControl(c).ok());
  EXPECT_FALSE(src->state().paused);
  c.command = protocol::ControlCommand::kRequestKeyFrame;
  out_.clear();
  ASSERT_TRUE(src->ApplyControl(c).ok());
  Pump(*src);
  EXPECT_EQ(Meshes().size(), 1u);
  c.command = protocol::ControlCommand::kSetLoop;
  c.value = 1;
  ASSERT_TRUE(src->ApplyControl(c).ok());
  EXPECT_TRUE(src->state().loop);
  c.value = 0;
  ASSERT_TRUE(src->ApplyControl(c).ok());
  EXPECT_FALSE(src->state().loop);
  c.command = protocol::ControlCommand::kSubscribe;
  EXPECT_EQ(src->ApplyControl(c).code(), StatusCode::kInvalidArgument);
  c.command = protocol::ControlCommand::kSeek;
  c.value = -5;
  EXPECT_EQ(src->ApplyControl(c).code(), StatusCode::kOutOfRange);
}

TEST_F(ReplayTest, PushModeRunsOnTheClockAndStops) {
  Make(30);
  auto src = Source();
  const int64_t start = clock_.NowUs();
  Status s = src->Run([&](std::shared_ptr<const std::vector<uint8_t>> b, protocol::Header h) {
    out_.push_back({clock_.NowUs(), h, std::move(b)});
  });
  ASSERT_TRUE(s.ok()) << s.ToString();
  ASSERT_EQ(out_.size(), msgs_.size());
  for (size_t i = 0; i < out_.size(); ++i)
    EXPECT_EQ(out_[i].clock_us - start, msgs_[i].time_us) << i;  // SleepUntilUs lands exactly
  // Stop() from the callback ends a looping replay.
  out_.clear();
  ReplayOptions o;
  o.loop = true;
  auto looping = Source(o);
  s = looping->Run([&](std::shared_ptr<const std::vector<uint8_t>> b, protocol::Header h) {
    out_.push_back({clock_.NowUs(), h, std::move(b)});
    if (out_.size() == 500) looping->Stop();
  });
  ASSERT_TRUE(s.ok());
  EXPECT_EQ(out_.size(), 500u);
}

TEST_F(ReplayTest, ControlsFromAnotherThreadWhileRunning) {
  Make(30);
  RealClock& real = RealClock::Instance();
  ReplayOptions o;
  o.loop = true;
  o.speed = 4;
  auto s = ReplaySource::Create(reader_, &real, o);
  ASSERT_TRUE(s.ok());
  ReplaySource& src = **s;
  std::atomic<size_t> n{0};
  std::thread runner([&] {
    Status st = src.Run([&](std::shared_ptr<const std::vector<uint8_t>>, protocol::Header) { ++n; });
    EXPECT_TRUE(st.ok()) << st.ToString();
  });
  for (int i = 0; i < 50; ++i) {
    src.Pause();
    EXPECT_TRUE(src.Seek((i * 37000) % reader_->summary().duration_us).ok());
    EXPECT_TRUE(src.SetSpeed(i % 2 ? 0.5 : 4.0).ok());
    src.Resume();
    std::this_thread::sleep_for(std::chrono::milliseconds(2));
  }
  src.Stop();
  runner.join();
  EXPECT_GT(n.load(), 0u);  // controls are noticed within one 20 ms sleep slice
}

TEST_F(ReplayTest, SeekEmitsTheRigInEffect) {
  // Calibration changes half-way: a second Rig (another name) in the stream.
  dir_ = test::MakeTempDir("record_rig2");
  msgs_ = test::MakeTestStream(60);
  Rig rig2 = test::SampleRig();
  rig2.name = "recalibrated";
  protocol::Header h;
  h.sequence = 1;
  h.capture_time_us = 1000000;
  size_t at = 0;
  while (msgs_[at].time_us < 1000000) ++at;
  msgs_.insert(msgs_.begin() + static_cast<std::ptrdiff_t>(at),
               {1000000, protocol::EncodeMessage(h, protocol::RigMessage{rig2}), MessageType::kRig});
  test::WriteTestRecording(dir_ + "/r.hrec", msgs_);
  auto r = RecordingReader::Open(dir_ + "/r.hrec");
  ASSERT_TRUE(r.ok());
  reader_ = std::shared_ptr<const RecordingReader>(std::move(*r));
  EXPECT_EQ(reader_->rig().name, "test-rig");
  auto src = Source();
  auto rig_name = [&](const Emitted& e) {
    auto m = protocol::DecodeMessage(*e.bytes);
    HOLO_CHECK(m.ok());
    return std::get<protocol::RigMessage>(m->payload).rig.name;
  };
  ASSERT_TRUE(src->Seek(1500000).ok());
  Pump(*src);
  ASSERT_FALSE(out_.empty());
  EXPECT_EQ(rig_name(out_[0]), "recalibrated");
  out_.clear();
  ASSERT_TRUE(src->Seek(500000).ok());
  Pump(*src);
  ASSERT_FALSE(out_.empty());
  EXPECT_EQ(rig_name(out_[0]), "test-rig");
}

TEST_F(ReplayTest, DamageFoundWhileReplayingEndsItWithAnError) {
  Make(30);
  // Flip a byte inside a late message of the (clean, index-opened) file.
  auto bytes = test::ReadBytes(dir_ + "/r.hrec");
  const auto& idx = reader_->summary().index;
  bytes[idx[20].offset + kRecordHeaderSize + 50] ^= 1;
  test::WriteBytes(dir_ + "/d.hrec", bytes, bytes.size());
  auto r = RecordingReader::Open(dir_ + "/d.hrec");
  ASSERT_TRUE(r.ok());
  auto src = ReplaySource::Create(std::shared_ptr<const RecordingReader>(std::move(*r)), &clock_);
  ASSERT_TRUE(src.ok());
  Status error;
  size_t n = 0;
  for (int i = 0; i < 2000 && error.ok(); ++i) {
    auto k = (*src)->Pump([&](std::shared_ptr<const std::vector<uint8_t>>, protocol::Header) { ++n; });
    if (!k.ok()) error = k.status();
    clock_.AdvanceUs(1000);
  }
  ASSERT_FALSE(error.ok());
  EXPECT_EQ(error.code(), StatusCode::kDataLoss);
  EXPECT_NE(error.message().find("checksum"), std::string::npos) << error.message();
  EXPECT_GT(n, 20u);
  // Seeking past the damage recovers.
  ASSERT_TRUE((*src)->Seek(idx[25].time_us).ok());
  auto k = (*src)->Pump([&](std::shared_ptr<const std::vector<uint8_t>>, protocol::Header) {});
  EXPECT_TRUE(k.ok());
}

}  // namespace
}  // namespace holo::record
