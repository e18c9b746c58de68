// G1 on what a site really sends: meshes fused from the studio's pods with
// the site's own segmentation (non-manifold edges, slivers, small
// fragments), both the full marching-cubes mesh and the compact stream mesh,
// over several frames of both standard workloads. Every frame must round-trip:
// same triangles (as vertex triples), positions within the quantisation bound,
// colours within the chroma bound.
#include <algorithm>
#include <array>
#include <cmath>
#include <vector>

#include <gtest/gtest.h>

#include "protocol/geometry_codec.h"
#include "server/capture/prerendered.h"
#include "server/pipeline/capture_site.h"
#include "studio/studio.h"
#include "studio/workloads.h"

namespace holo {
namespace {

// Number of edges used by other than two triangles (0 for a closed manifold).
size_t IrregularEdges(const Mesh& m) {
  std::vector<std::pair<uint32_t, uint32_t>> e;
  for (const auto& t : m.triangles)
    for (int k = 0; k < 3; ++k) e.emplace_back(std::min(t[k], t[(k + 1) % 3]), std::max(t[k], t[(k + 1) % 3]));
  std::sort(e.begin(), e.end());
  size_t irregular = 0;
  for (size_t i = 0; i < e.size();) {
    size_t j = i;
    while (j < e.size() && e[j] == e[i]) ++j;
    irregular += (j - i) != 2;
    i = j;
  }
  return irregular;
}

void ExpectRoundTrip(const Mesh& in, const char* what) {
  SCOPED_TRACE(what);
  protocol::GeometryEncodeOptions o;  // the site's defaults: G1, 1 mm, normals recomputed, colours
  std::vector<uint8_t> blob;
  std::vector<uint32_t> map;
  ASSERT_TRUE(protocol::EncodeGeometry(in, o, &blob, &map).ok());
  Mesh out;
  const Status s = protocol::DecodeGeometry(blob, &out);
  ASSERT_TRUE(s.ok()) << s.ToString();
  ASSERT_TRUE(out.Validate().ok());
  ASSERT_EQ(out.num_triangles(), in.num_triangles());
  double max_mm = 0;
  int color_max = 0;
  for (size_t i = 0; i < in.num_vertices(); ++i) {
    ASSERT_NE(map[i], UINT32_MAX) << "every vertex of a fused mesh is used by a triangle";
    max_mm = std::max(max_mm, 1e3 * static_cast<double>((in.positions[i] - out.positions[map[i]]).norm()));
    if (!in.colors.empty())
      for (int c = 0; c < 3; ++c) color_max = std::max(color_max, std::abs(in.colors[i][c] - out.colors[map[i]][c]));
  }
  EXPECT_LE(max_mm, 1.0 * std::sqrt(3.0) / 2 + 1e-3);
  EXPECT_LE(color_max, 1);
  auto canon = [](std::array<uint32_t, 3> t) {
    return std::min({t, std::array<uint32_t, 3>{t[1], t[2], t[0]}, std::array<uint32_t, 3>{t[2], t[0], t[1]}});
  };
  std::vector<std::array<uint32_t, 3>> ta, tb;
  for (const auto& t : in.triangles) ta.push_back(canon({map[t[0]], map[t[1]], map[t[2]]}));
  for (const auto& t : out.triangles) tb.push_back(canon(t));
  std::sort(ta.begin(), ta.end());
  std::sort(tb.begin(), tb.end());
  EXPECT_EQ(ta, tb);
}

void RunWorkload(const std::string& name, int frames, int stride) {
  SCOPED_TRACE(name);
  auto workload = GetWorkload(name);
  ASSERT_TRUE(workload.ok());
  auto studio = SyntheticStudio::Create(workload->rig, workload->studio);
  ASSERT_TRUE(studio.ok());
  StudioOptions empty = workload->studio;
  empty.empty_room = true;
  auto empty_room = SyntheticStudio::Create(workload->rig, empty);
  ASSERT_TRUE(empty_room.ok());
  // Frames spread over the sequence: render every `stride`-th.
  auto frames_src = std::make_shared<std::vector<RgbdFrameSet>>();
  for (int k = 0; k < frames; ++k) {
    RgbdFrameSet f;
    (*studio)->RenderFrame(k * stride, &f, nullptr);
    f.frame_index = k * stride;
    frames_src->push_back(std::move(f));
  }
  PrerenderedSource source(workload->rig, frames_src, /*loop=*/false);
  CaptureSiteOptions options;
  options.tsdf.voxel_size = workload->voxel_size_m;
  options.stream_mesh = true;
  options.full_mesh = true;
  options.background_frames = 10;
  options.pipeline.serial = true;
  auto site = CaptureSite::Create(&source, empty_room->get(), nullptr, options);
  ASSERT_TRUE(site.ok()) << site.status().ToString();
  size_t irregular = 0, seen = 0;
  auto stats = (*site)->Run([&](const FrameWork& w) -> Status {
    ExpectRoundTrip(w.full_mesh, "full mesh");
    ExpectRoundTrip(w.mesh, "stream mesh");
    irregular += IrregularEdges(w.full_mesh);
    ++seen;
    return OkStatus();
  });
  ASSERT_TRUE(stats.ok()) << stats.status().ToString();
  EXPECT_EQ(seen, static_cast<size_t>(frames));
  // The test means something only if the fused meshes are not clean manifolds.
  EXPECT_GT(irregular, 0u) << "expected boundary or non-manifold edges in fused meshes";
}

TEST(FusedGeometryCodec, QvgaFramesRoundTrip) { RunWorkload("S8-QVGA", 4, 9); }
TEST(FusedGeometryCodec, VgaFramesRoundTrip) { RunWorkload("S8-VGA", 2, 13); }

}  // namespace
}  // namespace holo
