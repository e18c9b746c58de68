#include <gtest/gtest.h>
#include <cstdio>
#include "server/fusion/stream_mesh.h"
#include "server/texture/texturer.h"
#include "protocol/geometry_codec.h"
#include "common/clock.h"
#include "server/studio/studio.h"
#include "server/studio/workloads.h"
namespace holo {
TEST(Exp, G1) {
  auto workload = GetWorkload("S8-QVGA");
  auto studio = SyntheticStudio::Create(workload->rig, workload->studio);
  RgbdFrameSet frames; StudioGroundTruth gt;
  (*studio)->RenderFrame(12, &frames, &gt);
  for (size_t p = 0; p < frames.frames.size(); ++p) frames.frames[p].mask = gt.mask[p];
  TsdfOptions o; o.voxel_size = workload->voxel_size_m;
  TsdfVolume volume(o);
  ASSERT_TRUE(volume.Integrate(workload->rig, frames).ok());
  auto m = StreamMesher::Create(o, StreamMeshOptions{});
  Mesh s; ASSERT_TRUE((*m)->Make(volume, &s).ok());
  Texturer tex(workload->rig, TextureOptions{});
  ASSERT_TRUE(tex.Apply(frames, &s).ok());
  Mesh truth = gt.foreground_mesh;
  for (const Mesh* mesh : {&s, &truth})
  for (float step : {0.001f, 0.002f}) for (bool colors : {true, false}) {
    protocol::GeometryEncodeOptions g; g.position_step_m = step; g.colors = colors;
    std::vector<uint8_t> blob;
    double best = 1e9, bestd = 1e9;
    for (int r = 0; r < 5; ++r) {
      blob.clear();
      Stopwatch sw; ASSERT_TRUE(protocol::EncodeGeometry(*mesh, g, &blob).ok()); best = std::min(best, sw.ElapsedMs());
      Mesh out; Stopwatch sd; ASSERT_TRUE(protocol::DecodeGeometry(blob, &out).ok()); bestd = std::min(bestd, sd.ElapsedMs());
    }
    std::printf("%s: %zu verts %zu tris step %.0f mm colors %d: %zu B (%.1f bits/tri) enc %.2f dec %.2f ms\n", mesh == &s ? "stream" : "truth", mesh->num_vertices(), mesh->num_triangles(), step*1e3, colors, blob.size(), blob.size()*8.0/mesh->num_triangles(), best, bestd);
  }
}
}
