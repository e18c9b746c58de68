// WAV files for the voice tools, benches and tests: reading (untrusted files:
// every header field is checked), writing, and resampling to the 48 kHz the
// voice path runs at (libsoxr).
// The reader is our own rather than libsndfile: we accept only PCM and float
// WAV, and a short reader whose every check is ours (and fuzzed) is less to
// trust on untrusted files than a library of many formats.
#pragma once

#include <cstdint>
#include <span>
#include <string>
#include <vector>

#include "common/status.h"

namespace holo::audio {

// Largest WAV file read (bytes) and longest audio accepted (seconds): a bad
// header or an endless file cannot exhaust memory.
inline constexpr uint64_t kMaxWavFileBytes = 1ull << 30;
inline constexpr double kMaxWavSeconds = 3600.0;

struct WavAudio {
  int sample_rate = 0;
  int channels = 0;
  std::vector<float> samples;  // interleaved, [-1, 1]
  size_t frames() const { return channels > 0 ? samples.size() / static_cast<size_t>(channels) : 0; }
};

// Parses a RIFF/WAVE file held in memory: PCM 8/16/24/32-bit, IEEE float
// 32/64-bit, plain or WAVE_FORMAT_EXTENSIBLE; 1..32 channels; 1000..384000 Hz.
// DataLoss naming what is wrong (truncated chunks, inconsistent block size,
// unsupported format, no samples, ...). Safe on untrusted bytes.
StatusOr<WavAudio> ParseWav(std::span<const uint8_t> bytes);
// Reads and parses `path` (errors start with the path).
StatusOr<WavAudio> ReadWav(const std::string& path);

// Resamples mono `in` from `in_rate` to `out_rate` (libsoxr, high quality).
StatusOr<std::vector<float>> Resample(std::span<const float> in, int in_rate, int out_rate);

// Reads a WAV, mixes it to mono, resamples it to `target_rate`.
StatusOr<std::vector<float>> ReadMonoWav(const std::string& path, int target_rate);

// Writes 16-bit PCM WAVs (samples clipped to [-1, 1]).
Status WriteWav(const std::string& path, std::span<const float> interleaved, int channels, int sample_rate);
Status WriteStereoWav(const std::string& path, std::span<const float> interleaved, int sample_rate);
Status WriteMonoWav(const std::string& path, std::span<const float> mono, int sample_rate);

}  // namespace holo::audio
