#include <cstring>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include "common/file_util.h"
#include "common/mesh.h"
#include "test_util.h"

namespace holo {
namespace {

Mesh Tetrahedron(bool normals, bool colors) {
  Mesh m;
  m.positions = {{0, 0, 0}, {1.5f, 0, 0}, {0, -2.25f, 0}, {0.125f, 0.5f, 3.75f}};
  m.triangles = {{0, 2, 1}, {0, 1, 3}, {1, 2, 3}, {2, 0, 3}};
  if (normals) m.ComputeNormals();
  if (colors) m.colors = {{{255, 0, 0}}, {{0, 255, 0}}, {{0, 0, 255}}, {{12, 34, 56}}};
  return m;
}

void ExpectMeshEq(const Mesh& a, const Mesh& b) {
  ASSERT_EQ(a.positions.size(), b.positions.size());
  for (size_t i = 0; i < a.positions.size(); ++i) EXPECT_EQ(a.positions[i], b.positions[i]) << "vertex " << i;
  ASSERT_EQ(a.normals.size(), b.normals.size());
  for (size_t i = 0; i < a.normals.size(); ++i) EXPECT_EQ(a.normals[i], b.normals[i]) << "normal " << i;
  EXPECT_EQ(a.colors, b.colors);
  EXPECT_EQ(a.triangles, b.triangles);
}

TEST(Ply, WriteReadRoundTripIsExact) {
  const std::string dir = test::MakeTempDir("ply");
  for (bool n : {false, true})
    for (bool c : {false, true}) {
      const Mesh m = Tetrahedron(n, c);
      const std::string path = dir + "/m" + std::to_string(n) + std::to_string(c) + ".ply";
      ASSERT_TRUE(WritePly(path, m).ok());
      auto back = ReadPly(path);
      ASSERT_TRUE(back.ok()) << back.status().ToString();
      ExpectMeshEq(*back, m);
    }
  // Empty mesh.
  ASSERT_TRUE(WritePly(dir + "/empty.ply", Mesh()).ok());
  auto empty = ReadPly(dir + "/empty.ply");
  ASSERT_TRUE(empty.ok());
  EXPECT_TRUE(empty->empty());
}

TEST(Ply, ReadsAsciiWithQuadFaces) {
  const std::string dir = test::MakeTempDir("ply");
  const std::string text =
      "ply\nformat ascii 1.0\nelement vertex 4\nproperty float x\nproperty float y\nproperty float z\n"
      "element face 1\nproperty list uchar int vertex_indices\nend_header\n"
      "0 0 0\n1 0 0\n1 1 0\n0 1 0\n4 0 1 2 3\n";
  ASSERT_TRUE(WriteStringToFile(dir + "/quad.ply", text).ok());
  auto m = ReadPly(dir + "/quad.ply");
  ASSERT_TRUE(m.ok()) << m.status().ToString();
  EXPECT_EQ(m->num_vertices(), 4u);
  ASSERT_EQ(m->num_triangles(), 2u);
  EXPECT_NEAR(m->SurfaceArea(), 1.0, 1e-9);
}

// Every prefix of a valid binary PLY either fails with an error naming the
// file or (only for the full file) succeeds; none may crash or overrun.
TEST(Ply, EveryTruncatedPrefixIsAnError) {
  const std::string dir = test::MakeTempDir("ply");
  const std::string full_path = dir + "/full.ply";
  ASSERT_TRUE(WritePly(full_path, Tetrahedron(true, true)).ok());
  auto bytes = ReadFileToString(full_path);
  ASSERT_TRUE(bytes.ok());
  const std::string path = dir + "/prefix.ply";
  for (size_t n = 0; n < bytes->size(); ++n) {
    ASSERT_TRUE(WriteStringToFile(path, bytes->substr(0, n)).ok());
    auto m = ReadPly(path);
    ASSERT_FALSE(m.ok()) << "prefix of " << n << " of " << bytes->size() << " bytes was accepted";
    EXPECT_EQ(m.status().message().rfind(path, 0), 0u) << m.status().message();
  }
}

TEST(Ply, MalformedFilesGiveErrorsNamingTheFile) {
  const std::string dir = test::MakeTempDir("ply");
  const std::string header_v =
      "ply\nformat binary_little_endian 1.0\nelement vertex %s\nproperty float x\nproperty float y\n"
      "property float z\nelement face %s\nproperty list uchar uint vertex_indices\nend_header\n";
  auto make = [&](const char* nv, const char* nf, const std::string& body) {
    char buf[512];
    std::snprintf(buf, sizeof(buf), header_v.c_str(), nv, nf);
    return std::string(buf) + body;
  };
  std::string one_vertex(12, '\0');
  struct Case {
    const char* name;
    std::string content;
    const char* expect;
  };
  // A face referencing vertex 7 of 1.
  std::string bad_face(1, '\3');
  for (uint32_t i : {0u, 0u, 7u}) bad_face.append(reinterpret_cast<const char*>(&i), 4);
  std::string long_list(1, '\xff');
  const std::vector<Case> cases = {
      {"huge_vertices", make("4000000000", "0", one_vertex), "exceeds the file size"},
      {"huge_vertices64", make("18446744073709551615", "0", one_vertex), "exceeds the file size"},
      {"huge_faces", make("1", "99999999999", one_vertex + bad_face), "exceeds the file size"},
      {"negative_count", make("-1", "0", one_vertex), ""},
      {"bad_index", make("1", "1", one_vertex + bad_face), "references vertex 7"},
      {"not_ply", "hello world\n", "not a PLY file"},
      // Regression: an element without properties and a huge count used to loop for ever.
      {"empty_element_huge_count",
       "ply\nformat binary_little_endian 1.0\nelement foo 18446744073709551615\nend_header\n", "no vertex element"},
      {"no_end_header", "ply\nformat ascii 1.0\nelement vertex 1\n", "not a PLY file"},
      {"big_endian", "ply\nformat binary_big_endian 1.0\nend_header\n", "unsupported PLY format"},
      {"bad_type", "ply\nformat ascii 1.0\nelement vertex 1\nproperty quux x\nend_header\n", "unknown property type"},
      {"no_xyz", "ply\nformat ascii 1.0\nelement vertex 1\nproperty float q\nend_header\n1\n", "lacks x, y, z"},
      {"ascii_garbage",
       "ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\nproperty float z\n"
       "end_header\n1 2 abc\n",
       "truncated"},
  };
  for (const auto& c : cases) {
    const std::string path = dir + "/" + c.name + ".ply";
    ASSERT_TRUE(WriteStringToFile(path, c.content).ok());
    auto m = ReadPly(path);
    ASSERT_FALSE(m.ok()) << c.name;
    EXPECT_NE(m.status().message().find(path), std::string::npos) << c.name << ": " << m.status().message();
    EXPECT_NE(m.status().message().find(c.expect), std::string::npos) << c.name << ": " << m.status().message();
  }
  auto missing = ReadPly(dir + "/missing.ply");
  ASSERT_FALSE(missing.ok());
  EXPECT_EQ(missing.status().code(), StatusCode::kNotFound);
}

}  // namespace
}  // namespace holo
