// libFuzzer target: a voice frame (AudioPose payload, audio/voice_codec.h) as
// it arrives from the network: parsed, validated, then its audio decoded.
#include <cstddef>
#include <cstdint>
#include <memory>
#include <span>

#include "audio/voice_codec.h"
#include "common/status.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  auto frame = holo::audio::ParseVoiceFrame(std::span<const uint8_t>(data, size));
  if (!frame.ok()) return 0;
  HOLO_CHECK(holo::audio::ValidateVoiceFrame(*frame).ok());
  static auto opus = holo::audio::VoiceDecoder::Create(holo::audio::AudioCodec::kOpus);
  static auto pcm = holo::audio::VoiceDecoder::Create(holo::audio::AudioCodec::kPcm16);
  HOLO_CHECK(opus.ok() && pcm.ok());
  auto& decoder = holo::audio::IsOpus(frame->codec) ? *opus : *pcm;
  auto samples = decoder->Decode(frame->audio);
  if (samples.ok()) HOLO_CHECK(samples->size() == holo::audio::kFrameSamples);
  return 0;
}
