// A history of the most recent samples for statistics over a long run (a call
// or a site that runs for hours): memory and the cost of a median stay
// bounded, appending stays amortized O(1) and the order is kept.
#pragma once

#include <cstddef>
#include <utility>
#include <vector>

namespace holo {

// Appends `value` to `history`; with `keep` > 0 first drops the oldest `keep`
// entries whenever 2·`keep` are held, so `history` holds the newest `keep` to
// 2·`keep` samples. `keep` = 0 keeps everything.
template <typename T>
void AppendRecent(std::vector<T>* history, T value, size_t keep) {
  if (keep > 0 && history->size() >= 2 * keep)
    history->erase(history->begin(), history->begin() + static_cast<std::ptrdiff_t>(keep));
  history->push_back(std::move(value));
}

}  // namespace holo
