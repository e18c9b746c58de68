// libFuzzer target: the recording reader (server/record/recording_reader.h):
// opens the file (index or scan), then reads every message it lists.
#include <cstddef>
#include <cstdint>

#include "common/status.h"
#include "protocol/fuzz/fuzz_file.h"
#include "server/record/recording_reader.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  holo::record::RecordingReaderOptions options;
  options.max_message_bytes = 4u << 20;
  options.max_index_entries = 1u << 16;
  options.salvage = size % 2 == 1;  // both modes
  auto reader = holo::record::RecordingReader::Open(holo::fuzz::WriteInputFile(data, size, ".rec"), options);
  if (!reader.ok()) return 0;
  const auto& s = (*reader)->summary();
  HOLO_CHECK(s.data_end <= s.file_bytes);
  uint64_t offset = s.data_begin;
  for (uint64_t i = 0; i < s.num_messages && offset < s.data_end; ++i) {
    auto m = (*reader)->ReadAt(offset);
    if (!m.ok()) break;
    HOLO_CHECK(m->next_offset > offset);
    offset = m->next_offset;
  }
  return 0;
}
