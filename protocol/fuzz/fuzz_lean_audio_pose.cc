// libFuzzer target: a lean AudioPose payload (codec 3, PROTOCOL.md §9.1) as
// it arrives from the network: protocol FuzzLeanAudioPose (decode, invariants,
// encode back), then the audio path's ParseVoiceFrame under the same header
// and, when the frame validates, its Opus packet decoded. Seeds:
// protocol/fuzz/corpus/lean_audio_pose (written by tests/audio/lean_frame_test.cc).
#include <cstddef>
#include <cstdint>
#include <span>

#include "audio/voice_codec.h"
#include "common/status.h"
#include "protocol/fuzz_decoders.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const std::span<const uint8_t> payload(data, size);
  holo::protocol::FuzzLeanAudioPose(payload);
  holo::protocol::Header h;
  h.type = holo::protocol::MessageType::kAudioPose;
  h.sequence = 9;
  h.capture_time_us = 123456;
  auto frame = holo::audio::ParseVoiceFrame(h, payload);
  if (!frame.ok()) return 0;
  HOLO_CHECK(holo::audio::ValidateVoiceFrame(*frame).ok());
  static auto opus = holo::audio::VoiceDecoder::Create(holo::audio::AudioCodec::kOpusLean);
  static auto pcm = holo::audio::VoiceDecoder::Create(holo::audio::AudioCodec::kPcm16);
  HOLO_CHECK(opus.ok() && pcm.ok());
  auto& decoder = holo::audio::IsOpus(frame->codec) ? *opus : *pcm;
  auto samples = decoder->Decode(frame->audio);
  if (samples.ok()) HOLO_CHECK(samples->size() == holo::audio::kFrameSamples);
  return 0;
}
