// A two-site call with the loudspeaker settings on both sides: echo
// cancellation on (--aec on) and a personal HRTF (--hrtf FILE.sofa).
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <filesystem>

#include "audio/wav.h"
#include "client/net/participant.h"
#include "net/net_fixtures.h"
#include "net/session_server.h"
#include "test_util.h"

namespace holo {
namespace {

constexpr const char* kKemar = "/usr/share/libmysofa/MIT_KEMAR_normal_pinna.sofa";

TEST(CallAec, ParticipantsWithAecAndSofaHearEachOther) {
  ASSERT_TRUE(std::filesystem::exists(kKemar)) << kKemar << " missing: install libmysofa1 (scripts/setup.sh)";
  auto site_cfg = [] {
    net::ServerConfig c = test::LoopbackConfig(0);
    c.name = "call-aec-site";
    c.publisher_token = "pub";
    c.viewer_token = "view";
    c.threads = 1;
    return c;
  };
  auto site_a = net::Server::Start(site_cfg());
  auto site_b = net::Server::Start(site_cfg());
  ASSERT_TRUE(site_a.ok() && site_b.ok());
  const std::string dir = test::MakeTempDir("call_aec");
  auto config = [&](uint16_t local, uint16_t remote) {
    return "local: {name: here, address: 127.0.0.1:" + std::to_string(local) +
           ", publisher_token: pub}\nremote: {name: there, address: 127.0.0.1:" + std::to_string(remote) +
           ", viewer_token: view}\nroom: {preset: face-to-face, gap_m: 0.5}\n";
  };
  std::vector<std::unique_ptr<net::Participant>> people;
  for (int k = 0; k < 2; ++k) {
    auto call = net::ParseCallConfig(k == 0 ? config((*site_a)->port(), (*site_b)->port())
                                            : config((*site_b)->port(), (*site_a)->port()));
    ASSERT_TRUE(call.ok()) << call.status().ToString();
    net::ParticipantOptions po;
    po.call = *call;
    po.name = k == 0 ? "alice" : "bob";
    po.aec = true;
    // Speech, not the default 440 Hz tone: noise suppression removes a steady tone.
    po.audio_in = test::TestDataPath("audio/espeak_speech_22k.wav");
    po.hrtf_sofa = kKemar;
    // Only alice writes her output: with --aec the voices are rendered anyway.
    if (k == 0) po.audio_out = dir + "/alice.wav";
    auto p = net::Participant::Start(po);
    ASSERT_TRUE(p.ok()) << p.status().ToString();
    people.push_back(std::move(*p));
  }
  ASSERT_TRUE(test::Eventually([&] {
    return people[0]->stats().remote_audio_frames >= 100 && people[1]->stats().remote_audio_frames >= 100;
  }, 30.0));
  for (int k = 0; k < 2; ++k) {
    ASSERT_TRUE(people[k]->Stop().ok());
    const net::ParticipantStats s = people[k]->stats();
    EXPECT_GE(s.voice_frames_sent, 100);
    EXPECT_EQ(s.hrtf_status.rfind("sofa: ", 0), 0u) << s.hrtf_status;
    EXPECT_GT(s.output_rms, 1e-3) << "bob renders for the canceller even without --audio-out";
    // The own voice is a WAV, not a microphone: there is no echo
    // of the played audio in it, and the estimator must not invent a delay.
    EXPECT_LT(s.aec_delay_ms, 0.0);
  }
  auto wav = audio::ReadWav(dir + "/alice.wav");
  ASSERT_TRUE(wav.ok()) << wav.status().ToString();
  EXPECT_EQ(wav->channels, 2);
  EXPECT_FALSE(std::filesystem::exists(dir + "/bob.wav"));
}

}  // namespace
}  // namespace holo
