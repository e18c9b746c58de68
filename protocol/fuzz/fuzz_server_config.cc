// libFuzzer target: the session server YAML (net/server_config.h).
#include <cstddef>
#include <cstdint>
#include <string>

#include "net/server_config.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  (void)holo::net::ParseServerConfig(std::string(reinterpret_cast<const char*>(data), size));
  return 0;
}
