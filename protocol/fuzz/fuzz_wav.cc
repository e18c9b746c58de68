// libFuzzer target: the WAV parser (audio/wav.h). Anything it accepts has a
// sample count that matches its channels.
#include <cstddef>
#include <cstdint>
#include <span>

#include "audio/wav.h"
#include "common/status.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  auto wav = holo::audio::ParseWav(std::span<const uint8_t>(data, size));
  if (wav.ok()) HOLO_CHECK(wav->channels > 0 && wav->samples.size() % static_cast<size_t>(wav->channels) == 0);
  return 0;
}
