// holoport-web-fixture: test fixtures for the browser viewer (web/).
//
//   record  — a recording of the synthetic studio with everything a live site
//             sends: Rig, G1 MeshFrames (ground-truth mesh, per-vertex
//             colour), C1 ColorFrames (every pod's colour image and
//             foreground mask, through ColorEncoder) and PCM AudioPose.
//   golden  — decodes the first N MeshFrames and ColorFrames of a recording
//             with the C++ decoders and writes what they decode to, for the
//             JavaScript decoders' test (tests/web/decoders_test.mjs); with
//             --g3 N also N G3 geometry blobs of the studio's foreground (a
//             distance grid made from its ground-truth mesh), their C++
//             decodes, and the marching-cubes case table.
//   render  — the native renderer's image (client/render, as holoport-client
//             draws) of one frame of a recording from a fixed camera, PNG.
#include <algorithm>
#include <cmath>
#include <cstring>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <map>
#include <limits>
#include <memory>
#include <random>
#include <string>
#include <variant>
#include <vector>

#include <CLI/CLI.hpp>
#include <epoxy/gl.h>

#include "client/render/gl_context.h"
#include "client/render/renderer.h"
#include "common/image_io.h"
#include "common/log.h"
#include "common/marching_cubes_table.h"
#include "common/pose.h"
#include "common/sdf_grid.h"
#include "protocol/color_codec.h"
#include "protocol/geometry_codec.h"
#include "protocol/messages.h"
#include "protocol/surface_codec.h"
#include "protocol/video_codec.h"
#include "server/record/recording_reader.h"
#include "server/record/recording_writer.h"
#include "server/record/synthetic_stream.h"
#include "studio/studio.h"
#include "studio/workloads.h"

namespace holo {
namespace {

Status Record(const std::string& out, const std::string& workload, double seconds) {
  record::SyntheticStreamOptions so;
  so.workload = workload;
  HOLO_ASSIGN_OR_RETURN(auto stream, record::SyntheticStream::Create(so));
  HOLO_ASSIGN_OR_RETURN(Workload w, GetWorkload(workload));
  StudioOptions studio_options = w.studio;
  studio_options.threads = 2;
  studio_options.color_variation = false;  // a site calibrates its pods' colours
  HOLO_ASSIGN_OR_RETURN(auto studio, SyntheticStudio::Create(w.rig, studio_options));
  record::RecordingWriterOptions wo;
  wo.source = "synthetic:" + workload;
  HOLO_ASSIGN_OR_RETURN(auto writer, record::RecordingWriter::Create(out, wo, true));
  std::vector<protocol::ColorEncoder> encoders(w.rig.pods.size());
  uint32_t color_seq = 0;
  const auto end_us = static_cast<int64_t>(seconds * 1e6);
  for (;;) {
    record::StreamMessage m;
    HOLO_RETURN_IF_ERROR(stream->Next(&m));
    if (m.time_us > end_us) break;
    HOLO_RETURN_IF_ERROR(writer->WriteMessage(m.time_us, m.frame));
    if (m.type != protocol::MessageType::kMeshFrame) continue;
    // The frame's colour: every pod's noise-free image and exact mask in its colour camera.
    HOLO_ASSIGN_OR_RETURN(protocol::Header mh, protocol::DecodeHeader(m.frame.data(), 32));
    HOLO_ASSIGN_OR_RETURN(protocol::Payload mp, protocol::DecodePayload(mh.type, std::span<const uint8_t>(m.frame).subspan(32)));
    const auto& mf = std::get<protocol::MeshFrame>(mp);
    protocol::ColorFrame cf;
    cf.frame_index = mf.frame_index;
    cf.codec = protocol::ColorCodec::kC1;
    for (size_t i = 0; i < w.rig.pods.size(); ++i) {
      ImageRgb8 color;
      ImageGray8 mask;
      studio->RenderView(mf.frame_index, w.rig.pods[i].ColorCamera(), &color, nullptr, &mask);
      protocol::PodImage pi;
      pi.pod_id = static_cast<uint16_t>(w.rig.pods[i].id);
      HOLO_RETURN_IF_ERROR(encoders[i].Encode(color, mask, &pi.data));
      cf.images.push_back(std::move(pi));
    }
    protocol::Header ch;
    ch.stream_id = so.video_stream_id;
    ch.sequence = color_seq++;
    ch.capture_time_us = mh.capture_time_us;
    HOLO_RETURN_IF_ERROR(writer->WriteMessage(m.time_us, protocol::EncodeMessage(ch, cf)));
  }
  HOLO_RETURN_IF_ERROR(writer->Close());
  std::printf("wrote %s: %llu messages, %.1f s\n", out.c_str(),
              static_cast<unsigned long long>(writer->stats().messages), writer->stats().duration_us * 1e-6);
  return OkStatus();
}

template <typename T>
StatusOr<T> DecodeAs(const protocol::Header& h, const std::vector<uint8_t>& payload) {
  HOLO_ASSIGN_OR_RETURN(protocol::Payload p, protocol::DecodePayload(h.type, payload));
  if (!std::holds_alternative<T>(p)) return DataLoss("unexpected payload type");
  return std::get<T>(std::move(p));
}

Status WriteFile(const std::filesystem::path& path, const void* data, size_t size) {
  std::ofstream f(path, std::ios::binary);
  f.write(static_cast<const char*>(data), static_cast<std::streamsize>(size));
  if (!f) return Unavailable("cannot write " + path.string());
  return OkStatus();
}

// Every message of a recording, in order.
StatusOr<std::vector<std::pair<protocol::Header, std::vector<uint8_t>>>> ReadAll(const std::string& path) {
  HOLO_ASSIGN_OR_RETURN(auto reader, record::RecordingReader::Open(path));
  std::vector<std::pair<protocol::Header, std::vector<uint8_t>>> out;
  for (uint64_t off = reader->summary().data_begin; off < reader->summary().data_end;) {
    HOLO_ASSIGN_OR_RETURN(record::RecordedMessage m, reader->ReadAt(off));
    out.emplace_back(m.header, std::vector<uint8_t>(m.bytes->begin() + 32, m.bytes->end()));
    off = m.next_offset;
  }
  return out;
}

// mesh_K.bin: u32 nv, u32 nt, u32 has_normals, u32 has_colours, positions
// (f32), normals (f32, nv×3 or none), colours (u8), indices (u32).
std::vector<uint8_t> MeshBytes(const Mesh& mesh) {
  std::vector<uint8_t> b;
  auto put = [&b](const void* p, size_t n) {
    b.insert(b.end(), static_cast<const uint8_t*>(p), static_cast<const uint8_t*>(p) + n);
  };
  const auto nv = static_cast<uint32_t>(mesh.num_vertices()), nt = static_cast<uint32_t>(mesh.triangles.size());
  const uint32_t has_normals = mesh.normals.empty() ? 0 : 1, has_colors = mesh.colors.empty() ? 0 : 1;
  put(&nv, 4);
  put(&nt, 4);
  put(&has_normals, 4);
  put(&has_colors, 4);
  for (const auto& p : mesh.positions) put(p.data(), 12);
  for (const auto& n : mesh.normals) put(n.data(), 12);
  for (const auto& c : mesh.colors) put(c.data(), 3);
  for (const auto& t : mesh.triangles) put(t.data(), 12);
  return b;
}

// Golden files: mesh_K.bin (MeshBytes); color_K_P.bin = u32 w, u32 h, RGBA8
// (alpha = mask). GoldenVideo adds the V1 files.
Status Golden(const std::string& recording, const std::string& dir, int count) {
  std::filesystem::create_directories(dir);
  HOLO_ASSIGN_OR_RETURN(auto messages, ReadAll(recording));
  int meshes = 0, colors = 0;
  for (const auto& [h, payload] : messages) {
    if (h.type == protocol::MessageType::kMeshFrame && meshes < count) {
      HOLO_ASSIGN_OR_RETURN(protocol::MeshFrame mf, DecodeAs<protocol::MeshFrame>(h, payload));
      Mesh mesh;
      HOLO_RETURN_IF_ERROR(protocol::DecodeGeometry(mf.data, &mesh));
      const std::vector<uint8_t> b = MeshBytes(mesh);
      HOLO_RETURN_IF_ERROR(WriteFile(std::filesystem::path(dir) / ("mesh_" + std::to_string(mf.frame_index) + ".bin"),
                                     b.data(), b.size()));
      ++meshes;
    } else if (h.type == protocol::MessageType::kColorFrame && colors < count) {
      HOLO_ASSIGN_OR_RETURN(protocol::ColorFrame cf, DecodeAs<protocol::ColorFrame>(h, payload));
      for (const auto& im : cf.images) {
        ImageRgb8 image;
        ImageGray8 mask;
        HOLO_RETURN_IF_ERROR(protocol::DecodeColor(im.data, &image, &mask));
        std::vector<uint8_t> b(8 + size_t(image.width()) * image.height() * 4);
        const auto w = static_cast<uint32_t>(image.width()), hh = static_cast<uint32_t>(image.height());
        std::memcpy(b.data(), &w, 4);
        std::memcpy(b.data() + 4, &hh, 4);
        for (int y = 0; y < image.height(); ++y)
          for (int x = 0; x < image.width(); ++x) {
            uint8_t* d = &b[8 + (size_t(y) * image.width() + x) * 4];
            for (int c = 0; c < 3; ++c) d[c] = image.at(x, y, c);
            d[3] = mask.at(x, y);
          }
        HOLO_RETURN_IF_ERROR(WriteFile(std::filesystem::path(dir) / ("color_" + std::to_string(cf.frame_index) + "_" +
                                                                      std::to_string(im.pod_id) + ".bin"),
                                       b.data(), b.size()));
      }
      ++colors;
    }
  }
  std::printf("golden: %d meshes, %d colour frames in %s\n", meshes, colors, dir.c_str());
  return OkStatus();
}

// V1 golden files, for the JS V1 decoder: the first `count` colour frames'
// pod-0 images and masks (as the recording's C1 decodes them) coded as one
// V1 stream per mask format: v1_K_blocks.bin and v1_K_rows.bin (the blobs;
// frame 0 a keyframe, then delta frames) and v1mask_K.bin (u32 w, u32 h,
// the C++ decoder's mask, 0 or 255 per pixel).
Status GoldenVideo(const std::string& recording, const std::string& dir, int count) {
  HOLO_ASSIGN_OR_RETURN(auto messages, ReadAll(recording));
  std::unique_ptr<protocol::VideoEncoder> enc[2];
  protocol::VideoDecoder dec[2];
  for (int f = 0; f < 2; ++f) {
    protocol::VideoEncodeOptions o;
    o.mask_blocks = f == 0;
    HOLO_ASSIGN_OR_RETURN(enc[f], protocol::VideoEncoder::Create(o));
  }
  int k = 0;
  for (const auto& [h, payload] : messages) {
    if (h.type != protocol::MessageType::kColorFrame || k >= count) continue;
    HOLO_ASSIGN_OR_RETURN(protocol::ColorFrame cf, DecodeAs<protocol::ColorFrame>(h, payload));
    if (cf.images.empty()) continue;
    ImageRgb8 image;
    ImageGray8 mask;
    HOLO_RETURN_IF_ERROR(protocol::DecodeColor(cf.images[0].data, &image, &mask));
    for (int f = 0; f < 2; ++f) {
      std::vector<uint8_t> blob;
      HOLO_RETURN_IF_ERROR(enc[f]->Encode(image, mask, &blob));
      HOLO_RETURN_IF_ERROR(dec[f].Decode(blob));
      if (!(dec[f].mask() == dec[0].mask())) return Internal("v1 golden: the two mask formats decode differently");
      const std::string name = "v1_" + std::to_string(k) + (f == 0 ? "_blocks.bin" : "_rows.bin");
      HOLO_RETURN_IF_ERROR(WriteFile(std::filesystem::path(dir) / name, blob.data(), blob.size()));
    }
    const ImageGray8& m = dec[0].mask();
    std::vector<uint8_t> b(8 + size_t(m.width()) * m.height());
    const auto w = static_cast<uint32_t>(m.width()), hh = static_cast<uint32_t>(m.height());
    std::memcpy(b.data(), &w, 4);
    std::memcpy(b.data() + 4, &hh, 4);
    for (int y = 0; y < m.height(); ++y) std::memcpy(b.data() + 8 + size_t(y) * m.width(), m.row(y), size_t(m.width()));
    HOLO_RETURN_IF_ERROR(WriteFile(std::filesystem::path(dir) / ("v1mask_" + std::to_string(k) + ".bin"), b.data(), b.size()));
    ++k;
  }
  std::printf("golden v1: %d frames of pod 0 in both mask formats\n", k);
  return OkStatus();
}

// The recording with its colour as V1 video (the site's defaults but a
// keyframe every 30 frames): every ColorFrame's C1 images are decoded and
// coded again, one V1 stream per pod; a MeshFrame keeps its KEY_FRAME flag
// only where the pods' pictures are keyframes, as a V1 site sends them, so
// that segments start where the video decodes.
Status ToV1(const std::string& recording, const std::string& out) {
  HOLO_ASSIGN_OR_RETURN(auto reader, record::RecordingReader::Open(recording));
  record::RecordingWriterOptions wo;
  wo.source = "holoport-web-fixture to-v1";
  HOLO_ASSIGN_OR_RETURN(auto writer, record::RecordingWriter::Create(out, wo, true));
  protocol::VideoEncodeOptions vo;
  vo.keyframe_interval = 30;
  vo.crf = 32;
  std::map<uint16_t, std::unique_ptr<protocol::VideoEncoder>> video;
  std::map<uint16_t, std::pair<int, int>> picture_size;  // per pod, to count size changes (the browser reconfigures)
  int64_t size_changes = 0;
  uint32_t meshes = 0;
  for (uint64_t off = reader->summary().data_begin; off < reader->summary().data_end;) {
    HOLO_ASSIGN_OR_RETURN(record::RecordedMessage m, reader->ReadAt(off));
    off = m.next_offset;
    protocol::Header h = m.header;
    const std::vector<uint8_t> payload(m.bytes->begin() + 32, m.bytes->end());
    if (h.type == protocol::MessageType::kMeshFrame) {
      HOLO_ASSIGN_OR_RETURN(protocol::MeshFrame mf, DecodeAs<protocol::MeshFrame>(h, payload));
      const bool key = meshes++ % static_cast<uint32_t>(vo.keyframe_interval) == 0;
      h.flags = static_cast<uint16_t>(key ? (h.flags | protocol::kFlagKeyFrame) : (h.flags & ~protocol::kFlagKeyFrame));
      HOLO_RETURN_IF_ERROR(writer->WriteMessage(m.time_us, protocol::EncodeMessage(h, mf)));
    } else if (h.type == protocol::MessageType::kColorFrame) {
      HOLO_ASSIGN_OR_RETURN(protocol::ColorFrame cf, DecodeAs<protocol::ColorFrame>(h, payload));
      cf.codec = protocol::ColorCodec::kV1;
      bool key = !cf.images.empty();
      for (auto& im : cf.images) {
        ImageRgb8 image;
        ImageGray8 mask;
        HOLO_RETURN_IF_ERROR(protocol::DecodeColor(im.data, &image, &mask));
        auto& enc = video[im.pod_id];
        if (!enc) {
          HOLO_ASSIGN_OR_RETURN(enc, protocol::VideoEncoder::Create(vo));
        }
        im.data.clear();
        HOLO_RETURN_IF_ERROR(enc->Encode(image, mask, &im.data));
        HOLO_ASSIGN_OR_RETURN(protocol::VideoBlobInfo info, protocol::ParseVideoBlob(im.data));
        key = key && info.keyframe();
        auto& size = picture_size[im.pod_id];
        if (size.first != 0 && size != std::pair{info.window.w, info.window.h}) ++size_changes;
        size = {info.window.w, info.window.h};
      }
      h.flags = static_cast<uint16_t>(key ? (h.flags | protocol::kFlagKeyFrame) : (h.flags & ~protocol::kFlagKeyFrame));
      HOLO_RETURN_IF_ERROR(writer->WriteMessage(m.time_us, protocol::EncodeMessage(h, cf)));
    } else {
      HOLO_RETURN_IF_ERROR(writer->WriteMessage(m.time_us, *m.bytes));
    }
  }
  HOLO_RETURN_IF_ERROR(writer->Close());
  int64_t resizes = 0;
  for (const auto& [pod, enc] : video) resizes += enc->window_resizes();
  std::printf("wrote %s: %u mesh frames, colour as V1 (%zu pods, %lld picture sizes changed, %lld of them between "
              "keyframes)\n",
              out.c_str(), meshes, video.size(), static_cast<long long>(size_changes), static_cast<long long>(resizes));
  return OkStatus();
}

// Distance from p to the triangle (a, b, c).
double PointTriangleDistance(const Eigen::Vector3d& p, const Eigen::Vector3d& a, const Eigen::Vector3d& b,
                             const Eigen::Vector3d& c) {
  const Eigen::Vector3d n = (b - a).cross(c - a);
  const double n2 = n.squaredNorm();
  if (n2 > 0) {
    // Barycentric weights of a and b for p's projection onto the plane.
    const double wa = (c - b).cross(p - b).dot(n) / n2, wb = (a - c).cross(p - c).dot(n) / n2;
    if (wa >= 0 && wb >= 0 && wa + wb <= 1) return std::abs((p - a).dot(n)) / std::sqrt(n2);
  }
  auto segment = [&p](const Eigen::Vector3d& s, const Eigen::Vector3d& t) {
    const Eigen::Vector3d d = t - s;
    const double l2 = d.squaredNorm();
    const double h = l2 > 0 ? std::clamp((p - s).dot(d) / l2, 0.0, 1.0) : 0.0;
    return (p - s - h * d).norm();
  };
  return std::min({segment(a, b), segment(b, c), segment(c, a)});
}

// What fusion would leave of a closed mesh on a grid of `voxel`: signed
// distances clamped to ±trunc with a little noise, and samples deeper inside
// than `observed_depth` unobserved (NaN). The studio's figures are unions of
// overlapping closed parts, so inside is decided by the winding number along
// each grid row (not by the nearest triangle, whose side is ambiguous where
// parts overlap). `open_rows` counts rows whose winding does not return to 0
// (a hole in the mesh; 0 for the studio).
SdfGrid GridFromMesh(const Mesh& m, float voxel, float trunc, float observed_depth, float noise_m, size_t* open_rows) {
  Eigen::Vector3f lo = Eigen::Vector3f::Constant(std::numeric_limits<float>::infinity()), hi = -lo;
  for (const auto& p : m.positions) {
    lo = lo.cwiseMin(p);
    hi = hi.cwiseMax(p);
  }
  constexpr int kMargin = 3;
  SdfGrid g;
  g.voxel_m = voxel;
  // A fraction of a voxel off the bounding box, so that no row of samples
  // runs through the extreme vertices (a crossing there would count twice).
  g.origin = lo - voxel * Eigen::Vector3f(kMargin + 0.37f, kMargin + 0.61f, kMargin + 0.29f);
  g.nx = static_cast<int>(std::ceil((hi.x() - lo.x()) / voxel)) + 2 * kMargin + 1;
  g.ny = static_cast<int>(std::ceil((hi.y() - lo.y()) / voxel)) + 2 * kMargin + 1;
  g.nz = static_cast<int>(std::ceil((hi.z() - lo.z()) / voxel)) + 2 * kMargin + 1;
  std::vector<Eigen::Vector3d> q(m.positions.size());  // grid coordinates
  for (size_t i = 0; i < q.size(); ++i) q[i] = ((m.positions[i] - g.origin) / voxel).cast<double>();
  double volume = 0;
  for (const auto& t : m.triangles) volume += q[t[0]].dot(q[t[1]].cross(q[t[2]]));
  const double outward = volume > 0 ? 1.0 : -1.0;
  // Per row (y, z): where the row crosses the surface, +1 entering, −1 leaving.
  std::vector<std::vector<std::pair<double, int>>> rows(static_cast<size_t>(g.ny) * static_cast<size_t>(g.nz));
  auto area2 = [](const Eigen::Vector3d& a, const Eigen::Vector3d& b, double y, double z) {
    return (a.y() - y) * (b.z() - z) - (a.z() - z) * (b.y() - y);
  };
  for (const auto& t : m.triangles) {
    const Eigen::Vector3d &a = q[t[0]], &b = q[t[1]], &c = q[t[2]];
    const double n_x = (b.y() - a.y()) * (c.z() - a.z()) - (b.z() - a.z()) * (c.y() - a.y());
    if (n_x == 0) continue;
    const int y0 = std::max(0, static_cast<int>(std::ceil(std::min({a.y(), b.y(), c.y()}))));
    const int y1 = std::min(g.ny - 1, static_cast<int>(std::floor(std::max({a.y(), b.y(), c.y()}))));
    const int z0 = std::max(0, static_cast<int>(std::ceil(std::min({a.z(), b.z(), c.z()}))));
    const int z1 = std::min(g.nz - 1, static_cast<int>(std::floor(std::max({a.z(), b.z(), c.z()}))));
    for (int z = z0; z <= z1; ++z)
      for (int y = y0; y <= y1; ++y) {
        const double wa = area2(b, c, y, z) / n_x, wb = area2(c, a, y, z) / n_x, wc = 1 - wa - wb;
        if (wa < 0 || wb < 0 || wc < 0) continue;
        rows[static_cast<size_t>(y) + static_cast<size_t>(g.ny) * static_cast<size_t>(z)].emplace_back(
            wa * a.x() + wb * b.x() + wc * c.x(), n_x * outward < 0 ? 1 : -1);
      }
  }
  std::vector<uint8_t> inside(g.size(), 0);
  *open_rows = 0;
  for (size_t r = 0; r < rows.size(); ++r) {
    auto& row = rows[r];
    std::sort(row.begin(), row.end());
    int winding = 0;
    size_t next = 0;
    for (int x = 0; x < g.nx; ++x) {
      for (; next < row.size() && row[next].first < x; ++next) winding += row[next].second;
      inside[r * static_cast<size_t>(g.nx) + static_cast<size_t>(x)] = winding > 0;
    }
    for (; next < row.size(); ++next) winding += row[next].second;
    *open_rows += winding != 0;
  }
  // Unsigned distances within the band that matters.
  std::vector<float> dist(g.size(), std::numeric_limits<float>::infinity());
  const double band = std::max(trunc, observed_depth) / voxel;
  for (const auto& t : m.triangles) {
    const Eigen::Vector3d &a = q[t[0]], &b = q[t[1]], &c = q[t[2]];
    const Eigen::Vector3d tlo = (a.cwiseMin(b).cwiseMin(c).array() - band).matrix();
    const Eigen::Vector3d thi = (a.cwiseMax(b).cwiseMax(c).array() + band).matrix();
    const int x0 = std::max(0, static_cast<int>(std::ceil(tlo.x())));
    const int y0 = std::max(0, static_cast<int>(std::ceil(tlo.y())));
    const int z0 = std::max(0, static_cast<int>(std::ceil(tlo.z())));
    const int x1 = std::min(g.nx - 1, static_cast<int>(thi.x()));
    const int y1 = std::min(g.ny - 1, static_cast<int>(thi.y()));
    const int z1 = std::min(g.nz - 1, static_cast<int>(thi.z()));
    for (int z = z0; z <= z1; ++z)
      for (int y = y0; y <= y1; ++y)
        for (int x = x0; x <= x1; ++x) {
          const Eigen::Vector3d p(static_cast<double>(x), static_cast<double>(y), static_cast<double>(z));
          float& d = dist[g.Index(x, y, z)];
          d = std::min(d, static_cast<float>(voxel * PointTriangleDistance(p, a, b, c)));
        }
  }
  std::mt19937 rng(7);
  std::normal_distribution<float> gauss(0.0f, noise_m);
  g.sdf.resize(g.size());
  for (size_t i = 0; i < g.size(); ++i) {
    if (inside[i] && dist[i] > observed_depth) {
      g.sdf[i] = std::nanf("");
      continue;
    }
    g.sdf[i] = std::clamp((inside[i] ? -dist[i] : dist[i]) + gauss(rng), -trunc, trunc);
  }
  return g;
}

// G3 golden files, for the JS G3 decoder: g3_K.geom (a G3 geometry blob of
// the studio's foreground at frame 20·K, on the stream mesh's grid) and
// g3mesh_K.bin (the C++ decode, as mesh_K.bin); the last has two figures and
// two props. mc_table.bin: per case 0..255, u8 triangles and 36 u8 edges
// (common/marching_cubes_table.h), which the JS generates for itself.
Status GoldenSurface(const std::string& dir, const std::string& workload, int count) {
  std::filesystem::create_directories(dir);
  std::vector<uint8_t> table;
  for (int i = 0; i < 256; ++i) {
    const McCase& c = McTableCase(i);
    table.push_back(c.num_triangles);
    table.insert(table.end(), c.edges, c.edges + 3 * kMcMaxTriangles);
  }
  HOLO_RETURN_IF_ERROR(WriteFile(std::filesystem::path(dir) / "mc_table.bin", table.data(), table.size()));
  HOLO_ASSIGN_OR_RETURN(Workload w, GetWorkload(workload));
  StudioOptions so = w.studio;
  so.threads = 1;
  std::unique_ptr<SyntheticStudio> studio;
  for (int k = 0; k < count; ++k) {
    if (k == 0 || (k == count - 1 && count > 1)) {
      if (k > 0) {
        so.num_figures = 2;
        so.num_props = 2;
      }
      HOLO_ASSIGN_OR_RETURN(studio, SyntheticStudio::Create(w.rig, so));
    }
    const Mesh truth = studio->ForegroundMesh(20 * k);
    size_t open_rows = 0;
    // The stream mesh's grid: twice the workload's fusion voxel (StreamMeshOptions::step).
    const SdfGrid grid = GridFromMesh(truth, 2 * w.voxel_size_m, 0.032f, 0.05f, 0.0005f, &open_rows);
    if (open_rows) return Internal("the studio's mesh is not closed: " + std::to_string(open_rows) + " grid rows");
    std::vector<uint8_t> blob;
    protocol::SurfaceEncodeStats st;
    HOLO_RETURN_IF_ERROR(protocol::EncodeSurface(grid, protocol::SurfaceEncodeOptions{}, &blob, nullptr, &st));
    Mesh mesh;
    HOLO_RETURN_IF_ERROR(protocol::DecodeGeometry(blob, &mesh));
    const std::vector<uint8_t> b = MeshBytes(mesh);
    const std::string name = std::to_string(k);
    HOLO_RETURN_IF_ERROR(WriteFile(std::filesystem::path(dir) / ("g3_" + name + ".geom"), blob.data(), blob.size()));
    HOLO_RETURN_IF_ERROR(WriteFile(std::filesystem::path(dir) / ("g3mesh_" + name + ".bin"), b.data(), b.size()));
    std::printf("golden g3 %d: grid %d×%d×%d, %zu bytes, %zu vertices, %zu triangles (%zu cubes dropped)\n", k, grid.nx,
                grid.ny, grid.nz, blob.size(), mesh.num_vertices(), mesh.num_triangles(), st.dropped_cubes);
  }
  return OkStatus();
}

// The camera of the comparison (web/src/view.js builds the same one):
// eye, target (world, Z up), horizontal field of view, image size.
CameraModel FixedCamera(const std::vector<float>& eye, const std::vector<float>& target, double hfov, int w, int h) {
  CameraModel c;
  c.intrinsics = Intrinsics::FromFov(w, h, hfov);
  c.world_from_camera = LookAt(Eigen::Vector3f(eye[0], eye[1], eye[2]), Eigen::Vector3f(target[0], target[1], target[2]));
  return c;
}

Status Render(const std::string& recording, int64_t frame, const std::vector<float>& eye,
              const std::vector<float>& target, double hfov, int w, int h, const std::string& mode,
              const std::string& out) {
  HOLO_ASSIGN_OR_RETURN(auto messages, ReadAll(recording));
  protocol::RigMessage rig;
  bool have_rig = false, have_mesh = false, have_color = false;
  Mesh mesh;
  std::vector<ImageRgb8> images;
  std::vector<ImageGray8> masks;
  std::map<uint16_t, protocol::VideoDecoder> video;  // V1: one decoder per pod
  for (const auto& [hd, payload] : messages) {
    if (hd.type == protocol::MessageType::kRig && !have_rig) {
      HOLO_ASSIGN_OR_RETURN(rig, DecodeAs<protocol::RigMessage>(hd, payload));
      have_rig = true;
    } else if (hd.type == protocol::MessageType::kMeshFrame) {
      HOLO_ASSIGN_OR_RETURN(protocol::MeshFrame mf, DecodeAs<protocol::MeshFrame>(hd, payload));
      if (mf.frame_index != frame) continue;
      HOLO_RETURN_IF_ERROR(protocol::DecodeGeometry(mf.data, &mesh));
      have_mesh = true;
    } else if (hd.type == protocol::MessageType::kColorFrame) {
      HOLO_ASSIGN_OR_RETURN(protocol::ColorFrame cf, DecodeAs<protocol::ColorFrame>(hd, payload));
      if (cf.codec == protocol::ColorCodec::kV1) {
        // V1: every frame up to the wanted one goes through its pod's decoder.
        if (cf.frame_index > frame || have_color) continue;
        for (const auto& im : cf.images) {
          const Status st = video[im.pod_id].Decode(im.data);
          if (!st.ok() && cf.frame_index == frame) return st.WithContext("v1 frame " + std::to_string(frame));
        }
        if (cf.frame_index != frame) continue;
        for (const auto& im : cf.images) {
          images.push_back(video[im.pod_id].image());
          masks.push_back(video[im.pod_id].mask());
        }
        have_color = true;
        continue;
      }
      if (cf.frame_index != frame) continue;
      for (const auto& im : cf.images) {
        images.emplace_back();
        masks.emplace_back();
        HOLO_RETURN_IF_ERROR(protocol::DecodeColor(im.data, &images.back(), &masks.back()));
      }
      have_color = true;
    }
  }
  if (!have_rig || !have_mesh) return NotFound("frame " + std::to_string(frame) + " is not in " + recording);
  HOLO_ASSIGN_OR_RETURN(auto context, render::CreateHeadlessContext());
  HOLO_RETURN_IF_ERROR(context->MakeCurrent());
  HOLO_ASSIGN_OR_RETURN(auto renderer, render::Renderer::Create());
  HOLO_ASSIGN_OR_RETURN(auto target_fb, render::OffscreenTarget::Create(w, h));
  HOLO_RETURN_IF_ERROR(renderer->SetRemoteMesh(mesh));
  render::RenderSettings settings;
  settings.mode = render::ColorMode::kVertexColor;
  if (mode == "projective") {
    if (!have_color) return NotFound("frame " + std::to_string(frame) + " has no colour images");
    std::vector<const ImageRgb8*> ip;
    std::vector<const ImageGray8*> mp;
    for (size_t i = 0; i < images.size(); ++i) {
      ip.push_back(&images[i]);
      mp.push_back(&masks[i]);
    }
    HOLO_RETURN_IF_ERROR(renderer->SetPodImages(rig.rig, ip, mp));
    HOLO_RETURN_IF_ERROR(renderer->UpdateVisibility());
    settings.mode = render::ColorMode::kProjective;
    // The browser blends per fragment (with the view-dependent term): the
    // native reference does the same, not the baked atlas.
    settings.projective.bake = false;
  }
  target_fb->Bind();
  glViewport(0, 0, w, h);
  glClearColor(0, 0, 0, 1);
  glClear(GL_COLOR_BUFFER_BIT | GL_DEPTH_BUFFER_BIT);
  HOLO_RETURN_IF_ERROR(renderer->Render(FixedCamera(eye, target, hfov, w, h), settings, render::Viewport{0, 0, w, h}));
  ImageRgb8 image;
  HOLO_RETURN_IF_ERROR(target_fb->ReadRgb(&image));
  HOLO_RETURN_IF_ERROR(WriteImageRgb8(out, image));
  std::printf("rendered frame %lld (%zu triangles, %s) to %s\n", static_cast<long long>(frame), mesh.triangles.size(),
              mode.c_str(), out.c_str());
  return OkStatus();
}

}  // namespace
}  // namespace holo

int main(int argc, char** argv) {
  CLI::App app{"holoport-web-fixture: recordings, golden decodes and native renders for the browser viewer's tests"};
  holo::AddLogLevelOption(app);
  app.require_subcommand(0, 1);
  std::string out, recording, dir, workload = "S8-QVGA", mode = "vertex";
  double seconds = 8, hfov = 50;
  int count = 3, g3_count = 0, width = 640, height = 360;
  int64_t frame = 0;
  std::vector<float> eye{2.2f, -1.6f, 1.6f}, target{0.0f, 0.0f, 1.0f};
  auto* rec = app.add_subcommand("record", "write a recording of the synthetic studio with colour");
  rec->add_option("--out", out, "recording file to write")->required();
  rec->add_option("--workload", workload, "studio workload (S8-QVGA, S8-VGA, S4-QVGA)");
  rec->add_option("--seconds", seconds, "length, seconds")->check(CLI::Range(0.1, 600.0));
  auto* gold = app.add_subcommand("golden", "decode the first frames of a recording with the C++ decoders");
  gold->add_option("--recording", recording, "recording file")->required();
  gold->add_option("--out-dir", dir, "directory for the golden files")->required();
  gold->add_option("--count", count, "mesh and colour frames to write")->check(CLI::Range(1, 1000));
  gold->add_option("--g3", g3_count, "G3 blobs of the studio's foreground to write, with their decodes")
      ->check(CLI::Range(0, 100));
  gold->add_option("--workload", workload, "studio workload of the G3 blobs");
  auto* tov1 = app.add_subcommand("to-v1", "write a recording's colour as V1 video (a keyframe every 30 frames)");
  tov1->add_option("--recording", recording, "recording file to read")->required();
  tov1->add_option("--out", out, "recording file to write")->required();
  auto* ren = app.add_subcommand("render", "render one frame of a recording with the native renderer, PNG");
  ren->add_option("--recording", recording, "recording file")->required();
  ren->add_option("--frame", frame, "frame index (MeshFrame.frame_index)")->required();
  ren->add_option("--out", out, "PNG to write")->required();
  ren->add_option("--eye", eye, "camera position x,y,z (metres, Z up)")->expected(3)->delimiter(',');
  ren->add_option("--target", target, "point the camera looks at x,y,z")->expected(3)->delimiter(',');
  ren->add_option("--hfov", hfov, "horizontal field of view, degrees")->check(CLI::Range(5.0, 170.0));
  ren->add_option("--width", width, "image width")->check(CLI::Range(16, 4096));
  ren->add_option("--height", height, "image height")->check(CLI::Range(16, 4096));
  ren->add_option("--color", mode, "vertex or projective")->check(CLI::IsMember({"vertex", "projective"}));
  CLI11_PARSE(app, argc, argv);
  if (app.get_subcommands().empty()) {
    spdlog::error("holoport-web-fixture: give a subcommand (record, golden, to-v1 or render); --help lists them");
    return 2;
  }
  holo::Status s;
  if (*rec) s = holo::Record(out, workload, seconds);
  if (*gold) {
    s = holo::Golden(recording, dir, count);
    if (s.ok() && g3_count > 0) s = holo::GoldenSurface(dir, workload, g3_count);
    if (s.ok()) s = holo::GoldenVideo(recording, dir, count);
  }
  if (*tov1) s = holo::ToV1(recording, out);
  if (*ren) s = holo::Render(recording, frame, eye, target, hfov, width, height, mode, out);
  if (!s.ok()) {
    spdlog::error("holoport-web-fixture: {}", s.ToString());
    return 1;
  }
  return 0;
}
