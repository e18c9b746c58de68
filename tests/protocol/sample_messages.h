// One valid sample of every message type, plus small codec blobs, shared by
// the protocol tests.
#pragma once

#include <algorithm>
#include <cmath>
#include <string>
#include <utility>
#include <vector>

#include "common/rig.h"
#include "protocol/color_codec.h"
#include "protocol/depth_codec.h"
#include "protocol/fuzz_decoders.h"
#include "protocol/geometry_codec.h"
#include "protocol/messages.h"
#include "protocol/surface_codec.h"
#include "protocol/test_meshes.h"

namespace holo::test {

inline Rig SampleRig() {
  Rig rig;
  rig.name = "test-rig";
  for (int i = 0; i < 2; ++i) {
    PodCalibration p;
    p.id = i;
    p.name = "pod" + std::to_string(i);
    p.depth = Intrinsics::FromFov(320, 240, 70);
    p.color = Intrinsics::FromFov(640, 480, 70);
    p.color.distortion = {0.1, -0.02, 0.001, 0, 0.003};
    p.world_from_depth = Pose::Identity();
    p.world_from_depth.translation() = Eigen::Vector3f(1.0f * i, 2, 1.5f);
    p.world_from_depth.linear() = Eigen::AngleAxisf(0.3f * (i + 1), Eigen::Vector3f::UnitZ()).toRotationMatrix();
    rig.pods.push_back(p);
  }
  return rig;
}

// Two regions (a box being entered, a sphere empty), frame 42.
inline protocol::Regions SampleRegions() {
  using namespace protocol;
  Regions m;
  m.frame_index = 42;
  RegionReport box;
  box.name = "table";
  box.shape = RegionShape::kBox;
  box.a = {-0.5f, 0.2f, 0.7f};
  box.b = {0.5f, 0.8f, 1.1f};
  box.state = RegionState::kEnter;
  box.occupied_litres = 1.75f;
  RegionReport ball;
  ball.name = "lamp";
  ball.shape = RegionShape::kSphere;
  ball.a = {1.0f, -1.0f, 1.8f};
  ball.b = {0.25f, 0, 0};
  m.regions = {box, ball};
  return m;
}

inline std::vector<protocol::Payload> SamplePayloads() {
  using namespace protocol;
  std::vector<Payload> v;
  Hello h;
  h.role = Role::kPublisher;
  h.capabilities = {{GeometryCodec::kG0, GeometryCodec::kG1}, {ColorCodec::kC0, ColorCodec::kC1}, {AudioCodec::kOpus}};
  h.access_token = "publisher-token-123";
  h.client_name = "site-a";
  v.push_back(h);
  Welcome w;
  w.session_id = 0x1122334455667788ull;
  w.server_name = "site-b";
  v.push_back(w);
  Refuse r;
  r.reason = RefuseReason::kBadToken;
  r.message = "access token not accepted for role publisher";
  v.push_back(r);
  v.push_back(RigMessage{SampleRig()});
  MeshFrame mf;
  mf.frame_index = 42;
  GeometryEncodeOptions go;
  (void)EncodeGeometry(NoisySphere(4, 6), go, &mf.data);
  v.push_back(mf);
  ColorFrame cf;
  cf.frame_index = 42;
  ImageRgb8 im;
  ImageGray8 mask;
  MaskedImage(24, 16, &im, &mask);
  for (uint16_t p = 0; p < 2; ++p) {
    PodImage pi;
    pi.pod_id = p;
    (void)EncodeColor(im, mask, {}, &pi.data);
    cf.images.push_back(pi);
  }
  v.push_back(cf);
  AudioPose a;
  a.codec = AudioCodec::kOpus;
  a.sequence = 7;
  a.capture_time_us = 123456789;
  a.pose = {1.0f, 2.0f, 1.6f, 0.5f, -0.1f, 0.02f};
  a.audio.assign(80, 0xAB);
  v.push_back(a);
  AudioPose pcm = a;
  pcm.codec = AudioCodec::kPcm16;
  pcm.audio.assign(1920, 0x01);  // 20 ms mono at 48 kHz
  v.push_back(pcm);
  ClientPose cp;
  cp.time_us = 1000;
  cp.predicted_display_us = 21000;
  cp.position = {0.1f, 1.6f, 0.3f};
  cp.rotation = {0.70710678f, 0, 0.70710678f, 0};
  cp.fov_tan = {1.1f, 1.0f, 0.9f, 0.95f};
  v.push_back(cp);
  RenderedFrame rf;
  rf.frame_index = 9;
  rf.pose_time_us = 1000;
  rf.width = 24;
  rf.height = 16;
  rf.image = cf.images[0].data;
  rf.depth = {1, 2, 3, 4};
  v.push_back(rf);
  v.push_back(Control{ControlCommand::kSeek, 3, 5000000, 1.0f});
  v.push_back(Control{ControlCommand::kSetSpeed, 0, 0, 2.0f});
  v.push_back(Ping{99, 1234});
  v.push_back(Pong{99, 1234, 2000, 2100});
  Stats s;
  s.values = {{"fps", 30.0}, {"encode_ms", 4.5}};
  v.push_back(s);
  PodFrame pf;
  pf.pod_id = 3;
  pf.frame_number = 17;
  pf.capture_time_us = 1700000123;
  ImageDepth16 depth(24, 16);
  for (int y = 0; y < 16; ++y)
    for (int x = 0; x < 24; ++x) depth.at(x, y) = static_cast<uint16_t>(x * y % 5 == 0 ? 0 : 1000 + 3 * x + y);
  (void)EncodeDepth(depth, {}, &pf.depth);
  pf.color = cf.images[0].data;
  v.push_back(pf);
  v.push_back(SampleRegions());
  return v;
}

// Codec blobs as inputs of the fuzz entry point, named as the corpus seeds:
// geometry (G0, G1, G1 with normals sent) of NoisySphere(rows, cols), G3 of
// a ball's distance field, and
// colour (C0, C1) of MaskedImage(width, height).
inline std::vector<std::pair<std::string, std::vector<uint8_t>>> SampleCodecInputs(int rows, int cols, int width,
                                                                                   int height) {
  using namespace protocol;
  std::vector<std::pair<std::string, std::vector<uint8_t>>> out;
  const Mesh mesh = NoisySphere(rows, cols);
  for (GeometryCodec c : {GeometryCodec::kG0, GeometryCodec::kG1}) {
    GeometryEncodeOptions o;
    o.codec = c;
    std::vector<uint8_t> b;
    HOLO_CHECK(EncodeGeometry(mesh, o, &b).ok());
    out.emplace_back(c == GeometryCodec::kG0 ? "seed-geometry-g0" : "seed-geometry-g1",
                     FuzzInput(FuzzTarget::kGeometry, b));
  }
  {
    GeometryEncodeOptions o;
    o.normals = NormalMode::kTransmit;
    std::vector<uint8_t> b;
    HOLO_CHECK(EncodeGeometry(mesh, o, &b).ok());
    out.emplace_back("seed-geometry-g1-normals", FuzzInput(FuzzTarget::kGeometry, b));
  }
  {
    // G3: a ball's truncated distance field on a 16 mm grid of rows × cols × rows.
    SdfGrid g;
    g.voxel_m = 0.016f;
    g.nx = g.nz = rows + 4;
    g.ny = cols + 4;
    g.sdf.resize(g.size());
    const Eigen::Vector3f c = 0.5f * g.voxel_m * Eigen::Vector3f(g.nx - 1, g.ny - 1, g.nz - 1);
    const float r = 0.4f * g.voxel_m * static_cast<float>(std::min(g.nx, g.ny));
    for (int z = 0; z < g.nz; ++z)
      for (int y = 0; y < g.ny; ++y)
        for (int x = 0; x < g.nx; ++x) {
          const float d = (g.voxel_m * Eigen::Vector3f(x, y, z) - c).norm() - r;
          g.sdf[g.Index(x, y, z)] = d < -0.02f ? std::nanf("") : std::clamp(d, -0.032f, 0.032f);
        }
    SurfaceEncodeOptions o;
    o.min_component_triangles = 0;
    std::vector<uint8_t> b;
    HOLO_CHECK(EncodeSurface(g, o, &b).ok());
    out.emplace_back("seed-geometry-g3", FuzzInput(FuzzTarget::kGeometry, b));
  }
  ImageRgb8 im;
  ImageGray8 mask;
  MaskedImage(width, height, &im, &mask);
  for (ColorCodec c : {ColorCodec::kC0, ColorCodec::kC1}) {
    ColorEncodeOptions o;
    o.codec = c;
    std::vector<uint8_t> b;
    HOLO_CHECK(EncodeColor(im, mask, o, &b).ok());
    out.emplace_back(c == ColorCodec::kC0 ? "seed-color-c0" : "seed-color-c1", FuzzInput(FuzzTarget::kColor, b));
  }
  {
    ColorEncodeOptions o;  // C1 with the whole box in the JPEG (packed blocks are the default)
    o.pack_blocks = false;
    std::vector<uint8_t> b;
    HOLO_CHECK(EncodeColor(im, mask, o, &b).ok());
    out.emplace_back("seed-color-c1-box", FuzzInput(FuzzTarget::kColor, b));
  }
  return out;
}

}  // namespace holo::test
