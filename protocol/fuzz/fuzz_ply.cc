// libFuzzer target: the PLY reader (common/mesh.h). A mesh it accepts
// validates.
#include <cstddef>
#include <cstdint>

#include "common/mesh.h"
#include "protocol/geometry_codec.h"
#include "common/status.h"
#include "protocol/fuzz/fuzz_file.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  auto mesh = holo::ReadPly(holo::fuzz::WriteInputFile(data, size, ".ply"));
  if (mesh.ok()) HOLO_CHECK_MSG(holo::protocol::CheckMesh(*mesh).ok(), "PLY reader returned an invalid mesh");
  return 0;
}
