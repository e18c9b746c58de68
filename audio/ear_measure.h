// Interaural measurements of a rendered stereo signal: what a listener's two
// ears receive from a source, for tests and benchmarks of the spatializer.
#pragma once

#include <cstddef>
#include <vector>

namespace holo::audio {

struct EarMeasurement {
  double ild_db = 0;    // right − left level, dB
  double itd_ms = 0;    // lag of the left ear behind the right (> 0: source on the right), ms
  double level_db = 0;  // mean power of both ears, dB
};

// Measures interleaved stereo `stereo` (L, R, L, R, ...) over the frames
// [`begin`, `end`): level difference, and the time difference as the lag in
// ±`max_lag` samples that maximises the cross-correlation of the ears.
// Requires `begin` ≥ `max_lag` and `end` + `max_lag` ≤ the frame count
// (HOLO_CHECK).
EarMeasurement MeasureEars(const std::vector<float>& stereo, size_t begin, size_t end, int sample_rate,
                           int max_lag);

}  // namespace holo::audio
