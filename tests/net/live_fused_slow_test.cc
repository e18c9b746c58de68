// The live call on the reconstruction, end to end in one process: the real
// capture site (segmentation, fusion, stream mesh, texturing) on a short
// studio sequence encodes every frame in its encode stage and publishes it
// through the session server; a viewer on loopback decodes every frame.
// The decoded mesh must be as close to the studio's ground truth as the
// site's own mesh (the codec's quantisation is far below the fusion error),
// and frames must arrive in order with the site's capture times.
#include <algorithm>
#include <map>
#include <mutex>
#include <vector>

#include <gtest/gtest.h>

#include "common/metrics/mesh_distance.h"
#include "net/site_client.h"
#include "net_fixtures.h"
#include "server/capture/prerendered.h"
#include "server/net/site_publisher.h"
#include "server/pipeline/capture_site.h"
#include "studio/studio.h"
#include "studio/workloads.h"

namespace holo {
namespace {

// One quality layer: what is checked here is every frame on the full layer,
// not the layer policy (tests/net/fanout_layers_test.cc), which could move a
// viewer slowed by a loaded machine to the reduced layer.
net::SitePublisherOptions FullLayerOnly() {
  net::SitePublisherOptions o;
  o.reduced.enabled = false;
  return o;
}

struct SiteFrame {
  int64_t capture_us = 0;
  double chamfer_mm = 0;
  size_t triangles = 0;
};

TEST(LiveFused, ViewerDecodesEveryReconstructedFrameAsCloseToTruthAsTheSite) {
  constexpr int kFrames = 8;
  auto workload = GetWorkload("S8-QVGA");
  ASSERT_TRUE(workload.ok());
  auto studio = SyntheticStudio::Create(workload->rig, workload->studio);
  ASSERT_TRUE(studio.ok());
  StudioOptions empty = workload->studio;
  empty.empty_room = true;
  auto empty_room = SyntheticStudio::Create(workload->rig, empty);
  ASSERT_TRUE(empty_room.ok());
  auto source = PrerenderedSource::Render(**studio, kFrames, /*loop=*/false);
  ASSERT_TRUE(source.ok());

  auto server = test::StartServerRetrying(test::LoopbackConfig());
  ASSERT_TRUE(server.ok()) << server.status().ToString();
  (*server)->SetRig(workload->rig);
  net::SitePublisher publisher(server->get(), FullLayerOnly());

  std::mutex mu;
  std::vector<net::ReceivedFrame> received;
  net::ClientOptions co;
  co.port = (*server)->port();
  co.token = "view-secret";
  co.subscribe = net::kSubscribeGeometry | net::kSubscribeColor;
  co.max_pending_frames = 64;
  net::ClientCallbacks cb;
  cb.on_frame = [&](const net::ReceivedFrame& f) {
    std::lock_guard<std::mutex> l(mu);
    received.push_back(f);
  };
  auto client = net::SiteClient::Start(co, cb);
  ASSERT_TRUE(client.ok());
  ASSERT_TRUE((*client)->WaitConnected(10));
  ASSERT_TRUE(test::Eventually([&] { return (*server)->num_viewers() == 1; }, 10));

  CaptureSiteOptions options;
  options.tsdf.voxel_size = workload->voxel_size_m;
  options.stream_mesh = true;
  options.pipeline.max_frames = kFrames;
  // Slow enough that the viewer never falls behind (the fan-out would drop frames).
  options.pipeline.pace_fps = 10;
  auto site = CaptureSite::Create(source->get(), empty_room->get(), nullptr, options);
  ASSERT_TRUE(site.ok()) << site.status().ToString();

  std::map<int64_t, SiteFrame> sent;
  auto encode = [&](FrameWork& w) -> Status {
    if (!w.encoded) w.encoded = std::make_shared<net::EncodedFrame>();
    std::vector<net::PodColor> pods;
    for (const auto& f : w.frames.frames) pods.push_back({static_cast<uint16_t>(f.pod_id), &f.color, &f.mask});
    const int64_t capture_us = 1'000'000 + 33'333 * w.frames.frame_index;
    return publisher.Encode(w.frames.frame_index, capture_us, w.mesh, pods, static_cast<net::EncodedFrame*>(w.encoded.get()));
  };
  auto sink = [&](const FrameWork& w) -> Status {
    auto* e = static_cast<net::EncodedFrame*>(w.encoded.get());
    if (e == nullptr) return Internal("the encode stage did not run");
    SiteFrame s;
    s.capture_us = e->capture_wall_us;
    s.triangles = w.mesh.num_triangles();
    auto d = metrics::ComputeMeshDistance(w.mesh, (*studio)->ForegroundMesh(w.frames.frame_index));
    HOLO_RETURN_IF_ERROR(d.status());
    s.chamfer_mm = d->chamfer_mm;
    sent[w.frames.frame_index] = s;
    publisher.PublishEncoded(e);
    return OkStatus();
  };
  auto stats = (*site)->Run(sink, encode);
  ASSERT_TRUE(stats.ok()) << stats.status().ToString();
  ASSERT_EQ(stats->frames, kFrames);
  ASSERT_TRUE(test::Eventually([&] {
    std::lock_guard<std::mutex> l(mu);
    return received.size() >= static_cast<size_t>(kFrames);
  }, 20));
  (*client)->Stop();

  std::lock_guard<std::mutex> l(mu);
  ASSERT_EQ(received.size(), static_cast<size_t>(kFrames));
  for (size_t i = 0; i < received.size(); ++i) {
    const net::ReceivedFrame& f = received[i];
    SCOPED_TRACE("frame " + std::to_string(f.frame_index));
    EXPECT_EQ(f.frame_index, static_cast<int64_t>(i)) << "frames in order, none lost";
    ASSERT_TRUE(f.has_mesh);
    ASSERT_TRUE(f.has_color);
    EXPECT_EQ(f.images.size(), workload->rig.pods.size());
    const SiteFrame& s = sent.at(f.frame_index);
    EXPECT_EQ(f.capture_time_us, s.capture_us);
    EXPECT_EQ(f.mesh.num_triangles(), s.triangles);
    EXPECT_LE(s.triangles, StreamMeshOptions{}.max_triangles);
    auto d = metrics::ComputeMeshDistance(f.mesh, (*studio)->ForegroundMesh(f.frame_index));
    ASSERT_TRUE(d.ok());
    // Stated bound: G1's 1 mm quantisation moves the Chamfer distance by < 0.3 mm.
    EXPECT_NEAR(d->chamfer_mm, s.chamfer_mm, 0.3);
    EXPECT_LT(d->chamfer_mm, 10.0);
  }
}

}  // namespace
}  // namespace holo
