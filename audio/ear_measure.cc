#include "audio/ear_measure.h"

#include <cmath>

#include "common/status.h"

namespace holo::audio {

EarMeasurement MeasureEars(const std::vector<float>& y, size_t begin, size_t end, int sample_rate, int max_lag) {
  const size_t frames = y.size() / 2;
  HOLO_CHECK(max_lag >= 0 && begin >= static_cast<size_t>(max_lag) && begin < end &&
             end + static_cast<size_t>(max_lag) <= frames && sample_rate > 0);
  EarMeasurement e;
  double el = 0, er = 0;
  for (size_t i = begin; i < end; ++i) {
    el += y[2 * i] * y[2 * i];
    er += y[2 * i + 1] * y[2 * i + 1];
  }
  e.ild_db = 10 * std::log10(er / el);
  e.level_db = 10 * std::log10((el + er) / static_cast<double>(end - begin));
  int best = 0;
  double best_c = -1e30;
  for (int lag = -max_lag; lag <= max_lag; ++lag) {
    double c = 0;
    for (size_t i = begin; i < end; ++i) c += y[2 * i + 1] * y[2 * (i + static_cast<size_t>(static_cast<long>(lag)))];
    if (c > best_c) best_c = c, best = lag;
  }
  e.itd_ms = best * 1000.0 / sample_rate;
  return e;
}

}  // namespace holo::audio
