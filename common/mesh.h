// Triangle meshes in world coordinates (metres).
#pragma once

#include <array>
#include <cstdint>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "common/status.h"

namespace holo {

struct Mesh {
  std::vector<Eigen::Vector3f> positions;
  std::vector<Eigen::Vector3f> normals;              // empty or one per vertex
  std::vector<std::array<uint8_t, 3>> colors;        // empty or one per vertex, RGB8
  std::vector<std::array<uint32_t, 3>> triangles;    // counter-clockwise seen from outside

  size_t num_vertices() const { return positions.size(); }
  size_t num_triangles() const { return triangles.size(); }
  bool empty() const { return positions.empty(); }
  void Clear();
  // OK, or DataLoss naming the problem (index out of range, attribute count mismatch, NaN).
  Status Validate() const;
  // Recomputes per-vertex normals as area-weighted face normals.
  void ComputeNormals();
  // Total surface area, m².
  double SurfaceArea() const;
  // Appends `other` (indices shifted).
  void Append(const Mesh& other);
};

// Binary little-endian PLY: positions, optional normals and RGB colors,
// triangle faces. The reader accepts ASCII and binary_little_endian PLY with
// float/double vertex properties and triangle (or polygon, fan-split) faces,
// and is safe on untrusted files.
// Our own reader and writer: Debian packages no small PLY library (Open3D,
// VTK and PCL read PLY among far more), and the reader's bounds checks are
// fuzzed with the rest of our decoders.
Status WritePly(const std::string& path, const Mesh& mesh);
StatusOr<Mesh> ReadPly(const std::string& path);

}  // namespace holo
