// libFuzzer target: rig YAML (common/rig.h). A rig that parses survives a
// write and re-parse.
#include <cstddef>
#include <cstdint>
#include <string>

#include "common/rig.h"
#include "common/status.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const std::string text(reinterpret_cast<const char*>(data), size);
  auto rig = holo::ParseRigYaml(text, "fuzz");
  if (rig.ok()) HOLO_CHECK_MSG(holo::ParseRigYaml(holo::RigToYaml(*rig), "fuzz-again").ok(), "rig does not round-trip");
  return 0;
}
