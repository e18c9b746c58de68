// Quantiles of measured samples (latencies, delays, offsets) for statistics
// and benchmark figures: the one definition the programs, libraries and
// benchmarks share, so that a "p99" means the same everywhere.
#pragma once

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <vector>

namespace holo {

// Nearest-rank quantile `q` in [0, 1] of `values` (taken by value and
// reordered): the value of rank round(q · (n − 1)) in sorted order, so
// q = 0.5 of an even count is the upper of the two middle values. 0 for no
// values.
template <typename T>
double Quantile(std::vector<T> values, double q) {
  if (values.empty()) return 0.0;
  const double rank = std::clamp(q, 0.0, 1.0) * static_cast<double>(values.size() - 1);
  const auto k = std::min(values.size() - 1, static_cast<size_t>(rank + 0.5));
  std::nth_element(values.begin(), values.begin() + static_cast<std::ptrdiff_t>(k), values.end());
  return static_cast<double>(values[k]);
}

// Quantile `q` in [0, 1] of `values`, interpolated linearly between the two
// values whose ranks enclose q · (n − 1) in sorted order; `if_empty` for no
// values.
inline double InterpolatedQuantile(std::vector<double> values, double q, double if_empty = 0.0) {
  if (values.empty()) return if_empty;
  std::sort(values.begin(), values.end());
  const double rank = std::clamp(q, 0.0, 1.0) * static_cast<double>(values.size() - 1);
  const auto lo = static_cast<size_t>(std::floor(rank));
  const size_t hi = std::min(lo + 1, values.size() - 1);
  return values[lo] + (values[hi] - values[lo]) * (rank - static_cast<double>(lo));
}

}  // namespace holo
