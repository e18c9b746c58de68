#include "client/render/region_boxes.h"

#include <cmath>

#include <epoxy/gl.h>

#include "client/render/gl_util.h"
#include "client/render/view.h"

namespace holo::render {
namespace {

constexpr const char* kVs = R"(#version 330 core
layout(location = 0) in vec3 a_pos;
uniform mat4 u_clip_from_remote;
void main() { gl_Position = u_clip_from_remote * vec4(a_pos, 1.0); }
)";
constexpr const char* kFs = R"(#version 330 core
uniform vec4 u_color;
out vec4 o_color;
void main() { o_color = u_color; }
)";

using V = Eigen::Vector3f;

void BoxCorners(const V& lo, const V& hi, V c[8]) {
  for (int i = 0; i < 8; ++i) c[i] = V(i & 1 ? hi.x() : lo.x(), i & 2 ? hi.y() : lo.y(), i & 4 ? hi.z() : lo.z());
}

void BoxEdges(const V& lo, const V& hi, std::vector<float>* out) {
  V c[8];
  BoxCorners(lo, hi, c);
  static constexpr int kEdges[12][2] = {{0, 1}, {2, 3}, {4, 5}, {6, 7}, {0, 2}, {1, 3},
                                        {4, 6}, {5, 7}, {0, 4}, {1, 5}, {2, 6}, {3, 7}};
  for (const auto& e : kEdges)
    for (int k : e) out->insert(out->end(), {c[k].x(), c[k].y(), c[k].z()});
}

void BoxFaces(const V& lo, const V& hi, std::vector<float>* out) {
  V c[8];
  BoxCorners(lo, hi, c);
  static constexpr int kQuads[6][4] = {{0, 1, 3, 2}, {4, 5, 7, 6}, {0, 1, 5, 4},
                                       {2, 3, 7, 6}, {0, 2, 6, 4}, {1, 3, 7, 5}};
  for (const auto& q : kQuads)
    for (int k : {q[0], q[1], q[2], q[0], q[2], q[3]}) out->insert(out->end(), {c[k].x(), c[k].y(), c[k].z()});
}

void SphereCircles(const V& centre, float r, std::vector<float>* out) {
  constexpr int kSegments = 48;
  for (int axis = 0; axis < 3; ++axis) {
    for (int i = 0; i < kSegments; ++i) {
      for (int k : {i, i + 1}) {
        const float a = 2.0f * static_cast<float>(M_PI) * static_cast<float>(k) / kSegments;
        V p = centre;
        p[(axis + 1) % 3] += r * std::cos(a);
        p[(axis + 2) % 3] += r * std::sin(a);
        out->insert(out->end(), {p.x(), p.y(), p.z()});
      }
    }
  }
}

}  // namespace

RegionBoxes::~RegionBoxes() {
  if (vbo_) glDeleteBuffers(1, &vbo_);
  if (vao_) glDeleteVertexArrays(1, &vao_);
  if (program_) glDeleteProgram(program_);
}

StatusOr<std::unique_ptr<RegionBoxes>> RegionBoxes::Create() {
  std::unique_ptr<RegionBoxes> r(new RegionBoxes());
  HOLO_ASSIGN_OR_RETURN(r->program_, BuildProgram("region boxes", kVs, kFs));
  glGenVertexArrays(1, &r->vao_);
  glGenBuffers(1, &r->vbo_);
  glBindVertexArray(r->vao_);
  glBindBuffer(GL_ARRAY_BUFFER, r->vbo_);
  glEnableVertexAttribArray(0);
  glVertexAttribPointer(0, 3, GL_FLOAT, GL_FALSE, 3 * sizeof(float), nullptr);
  glBindVertexArray(0);
  HOLO_RETURN_IF_ERROR(CheckGlError("region boxes: create"));
  return r;
}

Status RegionBoxes::Draw(const std::vector<protocol::RegionReport>& regions, const CameraModel& camera,
                         const Eigen::Matrix4f& local_from_remote, float near_m, float far_m, const Viewport& vp) {
  if (regions.empty()) return OkStatus();
  glViewport(vp.x, vp.y, vp.width, vp.height);
  glEnable(GL_SCISSOR_TEST);
  glScissor(vp.x, vp.y, vp.width, vp.height);
  glUseProgram(program_);
  const Eigen::Matrix4f clip = ViewProjection(camera, near_m, far_m) * local_from_remote;
  glUniformMatrix4fv(glGetUniformLocation(program_, "u_clip_from_remote"), 1, GL_FALSE, clip.data());
  const GLint color = glGetUniformLocation(program_, "u_color");
  glBindVertexArray(vao_);
  glBindBuffer(GL_ARRAY_BUFFER, vbo_);
  glEnable(GL_DEPTH_TEST);
  glDepthFunc(GL_LEQUAL);
  glDepthMask(GL_FALSE);  // regions never hide the scene or each other
  glEnable(GL_BLEND);
  glBlendFunc(GL_SRC_ALPHA, GL_ONE_MINUS_SRC_ALPHA);
  std::vector<float> verts;
  auto draw = [&](GLenum mode, const std::array<float, 4>& rgba) {
    if (verts.empty()) return;
    glBufferData(GL_ARRAY_BUFFER, static_cast<GLsizeiptr>(verts.size() * sizeof(float)), verts.data(),
                 GL_STREAM_DRAW);
    glUniform4f(color, rgba[0], rgba[1], rgba[2], rgba[3]);
    glDrawArrays(mode, 0, static_cast<GLsizei>(verts.size() / 3));
  };
  for (const auto& r : regions) {
    const V a(r.a[0], r.a[1], r.a[2]);
    const bool on = RegionOccupied(r);
    if (r.shape == protocol::RegionShape::kBox) {
      const V b(r.b[0], r.b[1], r.b[2]);
      if (on) {
        verts.clear();
        BoxFaces(a, b, &verts);
        draw(GL_TRIANGLES, {1.0f, 0.55f, 0.1f, 0.28f});
      }
      verts.clear();
      BoxEdges(a, b, &verts);
    } else {
      verts.clear();
      SphereCircles(a, r.b[0], &verts);
    }
    draw(GL_LINES, on ? std::array<float, 4>{1.0f, 0.6f, 0.1f, 1.0f} : std::array<float, 4>{0.45f, 0.7f, 0.95f, 0.8f});
  }
  glDepthMask(GL_TRUE);
  glDisable(GL_BLEND);
  glBindVertexArray(0);
  return CheckGlError("region boxes: draw");
}

}  // namespace holo::render
