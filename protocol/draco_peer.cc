#include "protocol/draco_peer.h"

#include "protocol/geometry_codec.h"

#include <cmath>
#include <string>

#include <draco/compression/decode.h>
#include <draco/compression/encode.h>
#include <draco/mesh/mesh.h>

namespace holo::protocol {

int DracoBitsForStep(float extent_m, float step_m) {
  int bits = 1;
  while (bits < 30 && extent_m / static_cast<float>((1u << bits) - 1) > step_m) ++bits;
  return bits;
}

Status EncodeDraco(const Mesh& mesh, const DracoOptions& o, std::vector<uint8_t>* out) {
  HOLO_RETURN_IF_ERROR(CheckMesh(mesh));
  const auto n = static_cast<uint32_t>(mesh.num_vertices());
  draco::Mesh dm;
  dm.set_num_points(n);
  draco::GeometryAttribute pa;
  pa.Init(draco::GeometryAttribute::POSITION, nullptr, 3, draco::DT_FLOAT32, false, sizeof(float) * 3, 0);
  const int pid = dm.AddAttribute(pa, true, n);
  for (uint32_t i = 0; i < n; ++i) {
    dm.attribute(pid)->SetAttributeValue(draco::AttributeValueIndex(i), mesh.positions[i].data());
  }
  const bool normals = o.normals && !mesh.normals.empty();
  const bool colors = o.colors && !mesh.colors.empty();
  if (normals) {
    draco::GeometryAttribute na;
    na.Init(draco::GeometryAttribute::NORMAL, nullptr, 3, draco::DT_FLOAT32, false, sizeof(float) * 3, 0);
    const int nid = dm.AddAttribute(na, true, n);
    for (uint32_t i = 0; i < n; ++i) {
      dm.attribute(nid)->SetAttributeValue(draco::AttributeValueIndex(i), mesh.normals[i].data());
    }
  }
  if (colors) {
    draco::GeometryAttribute ca;
    ca.Init(draco::GeometryAttribute::COLOR, nullptr, 3, draco::DT_UINT8, true, 3, 0);
    const int cid = dm.AddAttribute(ca, true, n);
    for (uint32_t i = 0; i < n; ++i) {
      dm.attribute(cid)->SetAttributeValue(draco::AttributeValueIndex(i), mesh.colors[i].data());
    }
  }
  for (const auto& t : mesh.triangles) {
    dm.AddFace({draco::PointIndex(t[0]), draco::PointIndex(t[1]), draco::PointIndex(t[2])});
  }
  draco::Encoder enc;
  enc.SetAttributeQuantization(draco::GeometryAttribute::POSITION, o.position_bits);
  enc.SetAttributeQuantization(draco::GeometryAttribute::NORMAL, o.normal_bits);
  enc.SetSpeedOptions(o.speed, o.speed);
  draco::EncoderBuffer buf;
  const draco::Status s = enc.EncodeMeshToBuffer(dm, &buf);
  if (!s.ok()) return Internal(std::string("draco encode: ") + s.error_msg());
  out->assign(buf.data(), buf.data() + buf.size());
  return OkStatus();
}

Status DecodeDraco(std::span<const uint8_t> bytes, Mesh* mesh) {
  draco::DecoderBuffer db;
  db.Init(reinterpret_cast<const char*>(bytes.data()), bytes.size());
  draco::Decoder dec;
  auto r = dec.DecodeMeshFromBuffer(&db);
  if (!r.ok()) return DataLoss(std::string("draco decode: ") + r.status().error_msg());
  const std::unique_ptr<draco::Mesh> dm = std::move(r).value();
  ClearMesh(mesh);
  const uint32_t n = dm->num_points();
  const draco::PointAttribute* pa = dm->GetNamedAttribute(draco::GeometryAttribute::POSITION);
  const draco::PointAttribute* na = dm->GetNamedAttribute(draco::GeometryAttribute::NORMAL);
  const draco::PointAttribute* ca = dm->GetNamedAttribute(draco::GeometryAttribute::COLOR);
  if (!pa) return DataLoss("draco decode: no positions");
  mesh->positions.resize(n);
  if (na) mesh->normals.resize(n);
  if (ca) mesh->colors.resize(n);
  for (uint32_t i = 0; i < n; ++i) {
    const draco::PointIndex p(i);
    pa->ConvertValue<float, 3>(pa->mapped_index(p), mesh->positions[i].data());
    if (na) na->ConvertValue<float, 3>(na->mapped_index(p), mesh->normals[i].data());
    if (ca) ca->ConvertValue<uint8_t, 3>(ca->mapped_index(p), mesh->colors[i].data());
  }
  mesh->triangles.resize(dm->num_faces());
  for (uint32_t f = 0; f < dm->num_faces(); ++f) {
    const auto& face = dm->face(draco::FaceIndex(f));
    for (int c = 0; c < 3; ++c) mesh->triangles[f][c] = face[c].value();
  }
  return OkStatus();
}

}  // namespace holo::protocol
