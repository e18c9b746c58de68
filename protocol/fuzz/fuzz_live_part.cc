// libFuzzer target: the live broadcast's part parser
// (protocol/live_format.h, docs/broadcast.md §2).
#include <cstddef>
#include <cstdint>

#include "common/status.h"
#include "protocol/live_format.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  auto records = holo::record::ParseLiveRecords(std::span<const uint8_t>(data, size), 1u << 20);
  if (!records.ok()) return 0;
  size_t total = 0;
  for (const auto& r : *records) {
    HOLO_CHECK(r.frame.size() >= holo::protocol::kHeaderSize);
    HOLO_CHECK(r.frame.data() >= data && r.frame.data() + r.frame.size() <= data + size);
    total += r.frame.size() + 24;
  }
  HOLO_CHECK(total == size);
  return 0;
}
