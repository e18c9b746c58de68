// Draco (Google's mesh codec, Debian's libdraco 1.5.5) wrapped as a geometry
// peer for benchmarks and comparisons. It is not a wire codec of the protocol.
#pragma once

#include <cstdint>
#include <span>
#include <vector>

#include "common/mesh.h"
#include "common/status.h"

namespace holo::protocol {

struct DracoOptions {
  int position_bits = 11;  // quantization over the bounding box's largest extent
  int normal_bits = 8;
  int speed = 3;           // 0 (best) .. 10 (fastest); the CLI's -cl 7 is speed 3
  bool normals = true;
  bool colors = true;
};

// Position quantization bits for which Draco's step (extent / (2^bits - 1))
// is at most `step_m` on a mesh whose largest bounding-box extent is `extent_m`.
int DracoBitsForStep(float extent_m, float step_m);

Status EncodeDraco(const Mesh& mesh, const DracoOptions& options, std::vector<uint8_t>* out);
// Decodes Draco bytes (Draco's own decoder: not hardened by us, trusted input only).
Status DecodeDraco(std::span<const uint8_t> bytes, Mesh* mesh);

}  // namespace holo::protocol
