#include "audio/capture.h"

#include <gtest/gtest.h>

#include <cmath>
#include <numbers>

#include "audio/wav.h"
#include "test_util.h"

namespace holo::audio {
namespace {

// A head walking along +y at 1 m/s, turning at 1 rad/s: pose is a function of time.
HeadPose PoseAt(int64_t t_us) {
  const float t = static_cast<float>(t_us) * 1e-6f;
  return HeadPose{1.0f, t, 1.6f, t, 0.0f, 0.0f};
}

TEST(Capture, WavFramesCarryPoseSequenceAndCaptureTime) {
  const std::string dir = test::MakeTempDir("capture");
  // 0.5 s + 5 ms of a 440 Hz tone at 16 kHz stereo: resampled and mixed to 48 kHz mono.
  const int rate = 16000;
  const size_t n = rate / 2 + rate / 200;
  std::vector<float> st(2 * n);
  for (size_t i = 0; i < n; ++i) {
    st[2 * i] = st[2 * i + 1] = 0.4f * static_cast<float>(std::sin(2 * std::numbers::pi * 440.0 * i / rate));
  }
  ASSERT_TRUE(WriteStereoWav(dir + "/in.wav", st, rate).ok());
  SimulatedClock clock(5'000'000);
  std::vector<int64_t> asked;
  auto cap = VoiceCapture::OpenWav(dir + "/in.wav", clock, [&](int64_t t) {
    asked.push_back(t);
    return PoseAt(t - 5'000'000);
  });
  ASSERT_TRUE(cap.ok()) << cap.status().ToString();
  EXPECT_FALSE((*cap)->is_device());
  EXPECT_NE((*cap)->description().find("16000 Hz, 2 ch -> 48 kHz mono"), std::string::npos) << (*cap)->description();
  std::vector<float> all;
  uint32_t expect_seq = 0;
  for (;;) {
    auto f = (*cap)->Next();
    if (!f.ok()) {
      EXPECT_EQ(f.status().code(), StatusCode::kOutOfRange) << f.status().ToString();
      break;
    }
    EXPECT_EQ(f->sequence, expect_seq);
    EXPECT_EQ(f->samples.size(), static_cast<size_t>(kFrameSamples));
    const int64_t t0 = 5'000'000 + static_cast<int64_t>(expect_seq) * kFrameUs;
    EXPECT_EQ(f->capture_time_us, t0);
    EXPECT_EQ(clock.NowUs(), t0 + kFrameUs);  // returned once the 20 ms were complete
    const HeadPose want = PoseAt(t0 - 5'000'000);
    EXPECT_FLOAT_EQ(f->pose.y, want.y);
    EXPECT_FLOAT_EQ(f->pose.yaw, want.yaw);
    all.insert(all.end(), f->samples.begin(), f->samples.end());
    ++expect_seq;
  }
  // 505 ms at 48 kHz = 24240 samples: 25 full frames and a zero-padded 26th.
  EXPECT_EQ(expect_seq, 26u);
  EXPECT_EQ(asked.size(), 26u);
  int crossings = 0;
  for (size_t i = 4800; i < 19200; ++i) crossings += (all[i - 1] < 0) != (all[i] < 0);
  EXPECT_NEAR(crossings, 2 * 132, 2);  // 0.3 s of 440 Hz
  EXPECT_EQ(all.back(), 0.0f);         // padding
}

TEST(Capture, NoMicrophoneFailsOverToTheWavWithAClearNote) {
  const std::string dir = test::MakeTempDir("capture");
  ASSERT_TRUE(WriteMonoWav(dir + "/in.wav", std::vector<float>(4800, 0.1f), 48000).ok());
  SimulatedClock clock;
  auto pose = [](int64_t) { return HeadPose{}; };
  // A device name that cannot exist is refused with the reason and the device list.
  auto dev = VoiceCapture::OpenDevice("holoport-no-such-microphone", clock, pose);
  ASSERT_FALSE(dev.ok());
  EXPECT_EQ(dev.status().code(), StatusCode::kUnavailable);
  EXPECT_NE(dev.status().message().find("no microphone"), std::string::npos) << dev.status().message();
  EXPECT_NE(dev.status().message().find("holoport-no-such-microphone"), std::string::npos);
  CaptureOptions o;
  o.device = "holoport-no-such-microphone";
  o.wav_path = dir + "/in.wav";
  std::string note;
  auto cap = VoiceCapture::Open(o, clock, pose, &note);
  ASSERT_TRUE(cap.ok()) << cap.status().ToString();
  EXPECT_FALSE((*cap)->is_device());
  EXPECT_NE(note.find("no microphone"), std::string::npos) << note;
  EXPECT_NE(note.find("instead"), std::string::npos) << note;
  // Neither source: both reasons.
  o.wav_path = dir + "/missing.wav";
  auto none = VoiceCapture::Open(o, clock, pose);
  ASSERT_FALSE(none.ok());
  EXPECT_NE(none.status().message().find("no microphone"), std::string::npos);
  EXPECT_NE(none.status().message().find("missing.wav"), std::string::npos) << none.status().message();
  o.wav_path.clear();
  EXPECT_NE(VoiceCapture::Open(o, clock, pose).status().message().find("--audio-in"), std::string::npos);
  // A broken WAV is refused, not crashed on.
  {
    std::FILE* f = std::fopen((dir + "/bad.wav").c_str(), "wb");
    ASSERT_NE(f, nullptr);
    std::fputs("RIFF\x10\0\0\0WAVEfmt ", f);
    std::fclose(f);
  }
  auto bad = VoiceCapture::OpenWav(dir + "/bad.wav", clock, pose);
  ASSERT_FALSE(bad.ok());
  EXPECT_NE(bad.status().message().find("bad.wav"), std::string::npos);
}

}  // namespace
}  // namespace holo::audio
