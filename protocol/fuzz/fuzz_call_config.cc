// libFuzzer target: the two-site call YAML (client/net/call_config.h).
#include <cstddef>
#include <cstdint>
#include <string>

#include "client/net/call_config.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  (void)holo::net::ParseCallConfig(std::string(reinterpret_cast<const char*>(data), size), "fuzz");
  return 0;
}
