#include "client/render/renderer.h"

#include <algorithm>
#include <bit>
#include <cmath>
#include <cstring>
#include <string>

#include <epoxy/gl.h>

#include "client/render/atlas.h"
#include "client/render/gl_util.h"
#include "client/render/view.h"
#include "common/clock.h"
#include "common/worker_pool.h"
#include "texture/mesh_renderer.h"

namespace holo::render {
namespace {

// One vertex on the GPU: position, normal (floats) and RGBA8 colour.
struct GpuVertex {
  float p[3];
  float n[3];
  uint8_t c[4];
};
static_assert(sizeof(GpuVertex) == 28);

// The pods' lens model (as Intrinsics: k1, k2, p1, p2 in d, then k3) on
// normalized camera coordinates, shared by the draw and pod-depth shaders:
// they declare it and BuildProgram gets their source with this appended.
constexpr const char* kDistortGlsl = R"(
vec2 Distort(vec2 x, vec4 d, float k3) {
  float r2 = dot(x, x);
  float radial = 1.0 + r2 * (d.x + r2 * (d.y + r2 * k3));
  return vec2(x.x * radial + 2.0 * d.z * x.x * x.y + d.w * (r2 + 2.0 * x.x * x.x),
              x.y * radial + d.z * (r2 + 2.0 * x.y * x.y) + 2.0 * d.w * x.x * x.y);
}
)";

// The pods' blending weights are computed per vertex (as Holoportation
// does) and interpolated. The fragment shader transforms the surface point
// into each pod's camera, projects it (with distortion), tests visibility and
// discontinuities with one fetch of the flagged depth map and blends.
// (Interpolating the per-pod camera-frame points as varyings instead was no
// faster on llvmpipe and needs 4 varying components per pod.)
//
// A program is built per number of pod *slots* (SLOTS, defined when it is
// built; 0 = per-vertex colour only, also the depth pre-pass): each draw
// call covers the triangles that use the same set of pods (see
// Renderer::SelectPods), whose cameras are passed as slot uniforms. The
// loops over slots have a constant bound, so they are unrolled with static
// indices. llvmpipe runs every iteration of a fragment loop for the whole
// SIMD block whatever the weights (a `continue` saves nothing), so the cost
// per fragment is the number of slots, not the number of pods that matter.
constexpr const char* kDrawVs = R"(
layout(location = 0) in vec3 a_pos;
layout(location = 1) in vec3 a_normal;
layout(location = 2) in vec4 a_color;
// Bit i set: pod i may colour this vertex (its per-mesh selection).
layout(location = 3) in uint a_pods;
uniform mat4 u_clip_from_local;
uniform mat4 u_local_from_remote;
out vec3 v_color;
out vec3 v_remote;
invariant gl_Position;
#if SLOTS > 0
uniform vec3 u_slot_center[SLOTS];  // remote world
uniform int u_slot_pod[SLOTS];
uniform vec3 u_eye_remote;
uniform float u_alpha;
uniform float u_beta;
// Slot s's blending weight (0 = pod unusable) in component s % 4 of v_w[s / 4].
out vec4 v_w[(SLOTS + 3) / 4];
// pow() is costly on CPU renderers; the usual exponents are small integers.
float Pow(float x, float e) {
  if (e == 2.0) return x * x;
  if (e == 1.0) return x;
  if (e == 0.0) return 1.0;
  if (e == 4.0) return (x * x) * (x * x);
  return pow(x, e);
}
#endif
void main() {
  v_color = a_color.rgb;
  v_remote = a_pos;
  gl_Position = u_clip_from_local * (u_local_from_remote * vec4(a_pos, 1.0));
#if SLOTS > 0
  vec3 n = normalize(a_normal);
  vec3 to_eye = normalize(u_eye_remote - a_pos);
  for (int s = 0; s < (SLOTS + 3) / 4; ++s) v_w[s] = vec4(0.0);
  for (int s = 0; s < SLOTS; ++s) {
    vec3 to_pod = normalize(u_slot_center[s] - a_pos);
    float ndv = dot(n, to_pod);
    bool allowed = ((a_pods >> uint(u_slot_pod[s])) & 1u) != 0u;
    float w = allowed && ndv > 0.0 ? Pow(ndv, u_alpha) * Pow(max(0.5 * (1.0 + dot(to_pod, to_eye)), 1e-6), u_beta) : 0.0;
    v_w[s / 4][s % 4] = w;
  }
#endif
}
)";

constexpr const char* kDrawFs = R"(
in vec3 v_color;
in vec3 v_remote;
out vec4 o_color;
#if SLOTS > 0
in vec4 v_w[(SLOTS + 3) / 4];
uniform mat4 u_slot_cam_from_world[SLOTS];
uniform vec4 u_slot_intr[SLOTS];   // fx, fy, cx, cy
uniform vec4 u_slot_dist[SLOTS];   // k1, k2, p1, p2
uniform float u_slot_k3[SLOTS];
uniform vec2 u_slot_size[SLOTS];   // width, height (pixels)
uniform int u_slot_pod[SLOTS];     // texture array layer
uniform vec2 u_array_size;
uniform sampler2DArray u_pod_color;
uniform sampler2DArray u_pod_depth;
uniform float u_vis_tol;
uniform float u_edge_weight;
uniform bool u_distorted;
uniform float u_min_confidence;
vec2 Distort(vec2 x, vec4 d, float k3);  // kDistortGlsl, appended when the program is built
#endif

void main() {
#if SLOTS == 0
  o_color = vec4(v_color, 1.0);
#else
  vec3 acc = vec3(0.0);
  float acc_w = 0.0, sum_w = 0.0;
  for (int s = 0; s < SLOTS; ++s) {
    float w = v_w[s / 4][s % 4];
    if (w <= 1e-6) continue;
    // Without lens distortion the matrix holds the intrinsics too (pixel
    // x·z, y·z, z); with it, camera coordinates.
    vec3 pod = (u_slot_cam_from_world[s] * vec4(v_remote, 1.0)).xyz;
    if (pod.z < 0.05) continue;
    vec2 px = pod.xy / pod.z;
    if (u_distorted) {
      vec2 xn = Distort(px, u_slot_dist[s], u_slot_k3[s]);
      vec4 intr = u_slot_intr[s];
      px = vec2(intr.x * xn.x + intr.z, intr.y * xn.y + intr.w);
    }
    vec2 size = u_slot_size[s];
    if (px.x < -0.5 || px.y < -0.5 || px.x >= size.x - 0.5 || px.y >= size.y - 0.5) continue;
    // Flagged depth: camera z of the nearest surface, negative when that
    // texel is near a depth discontinuity (see kEdgeFs), 0 = nothing.
    int layer = u_slot_pod[s];
    float zf = texelFetch(u_pod_depth, ivec3(ivec2(floor(px + 0.5)), layer), 0).r;
    float zmap = abs(zf);
    if (zmap <= 0.0 || pod.z > zmap + u_vis_tol) continue;
    // Premultiplied by the texel's mask weight (alpha; 0 = background).
    vec4 c = texture(u_pod_color, vec3((px + 0.5) / u_array_size, float(layer)));
    // Near a depth discontinuity: used only when nothing clean is there.
    float k = zf < 0.0 ? u_edge_weight * w : w;
    acc += k * c.rgb;
    acc_w += k * c.a;
    sum_w += k;
  }
  if (acc_w > 0.0) {
    // Mean mask weight of the samples: where every pod saw this point only
    // at its mask's edge (a silhouette rim that every pod's segmentation
    // got wrong), the site's per-vertex colour (filled from the interior)
    // is more trustworthy than any of them.
    float confidence = acc_w / sum_w;
    o_color = vec4(mix(v_color, acc / acc_w, smoothstep(0.0, u_min_confidence, confidence)), 1.0);
  } else {
    o_color = vec4(v_color, 1.0);
  }
#endif
}
)";

// Visibility pre-pass: camera z of the nearest surface per pod pixel, with
// the pod's distortion applied to the vertices (straight edges between them,
// as the CPU rasterizer does).
constexpr const char* kDepthVs = R"(#version 330 core
layout(location = 0) in vec3 a_pos;
uniform mat4 u_cam_from_world;
uniform vec4 u_intr;
uniform vec4 u_dist;
uniform float u_k3;
uniform vec2 u_size;
uniform float u_near;
uniform float u_far;
out float v_z;
vec2 Distort(vec2 x, vec4 d, float k3);  // kDistortGlsl, appended when the program is built
void main() {
  vec4 pc = u_cam_from_world * vec4(a_pos, 1.0);
  float z = pc.z;
  v_z = z;
  vec2 xn = Distort(pc.xy / max(z, 1e-6), u_dist, u_k3);
  vec2 px = vec2(u_intr.x * xn.x + u_intr.z, u_intr.y * xn.y + u_intr.w);
  // Texel (u, v) of the map holds pixel (u, v): no vertical flip here.
  vec2 ndc = 2.0 * (px + 0.5) / u_size - 1.0;
  float zc = (u_far + u_near) / (u_far - u_near) * z - 2.0 * u_far * u_near / (u_far - u_near);
  // Points behind the camera are pushed outside the clip volume.
  gl_Position = z > u_near ? vec4(ndc * z, zc, z) : vec4(0.0, 0.0, -2.0, 1.0);
}
)";
constexpr const char* kDepthFs = R"(#version 330 core
in float v_z;
out float o_z;
void main() { o_z = v_z; }
)";

// Discontinuity flags, one full-screen pass per pod layer: reads the pod's
// depth map and writes it back negated where a neighbour at the radius
// (discontinuity_radius_m at the texel's depth, 1..8 pixels) is empty or
// differs by more than the jump. Done once per mesh, so the per-fragment
// test is a single fetch.
constexpr const char* kEdgeVs = R"(#version 330 core
void main() {
  // A triangle covering the viewport.
  vec2 p = vec2(gl_VertexID == 1 ? 3.0 : -1.0, gl_VertexID == 2 ? 3.0 : -1.0);
  gl_Position = vec4(p, 0.0, 1.0);
}
)";
constexpr const char* kEdgeFs = R"(#version 330 core
uniform sampler2DArray u_depth;
uniform int u_layer;
uniform vec2 u_size;
uniform float u_fx;
uniform float u_jump;
uniform float u_radius;
out float o_z;
void main() {
  ivec2 ip = ivec2(gl_FragCoord.xy);
  float z = texelFetch(u_depth, ivec3(ip, u_layer), 0).r;
  if (z <= 0.0) {
    o_z = 0.0;
    return;
  }
  const ivec2 kOffsets[8] = ivec2[8](ivec2(-1, 0), ivec2(1, 0), ivec2(0, -1), ivec2(0, 1),
                                     ivec2(-1, -1), ivec2(1, 1), ivec2(-1, 1), ivec2(1, -1));
  int r = clamp(int(ceil(u_radius * u_fx / z)), 1, 8);
  ivec2 maxp = ivec2(u_size) - 1;
  bool near_edge = false;
  for (int k = 0; k < 8; ++k) {
    float zq = texelFetch(u_depth, ivec3(clamp(ip + kOffsets[k] * r, ivec2(0), maxp), u_layer), 0).r;
    if (zq <= 0.0 || abs(zq - z) > u_jump) near_edge = true;
  }
  o_z = near_edge ? -z : z;
}
)";

// The baked atlas (ProjectiveOptions::bake): one bilinear fetch per pixel.
constexpr const char* kBakedVs = R"(#version 330 core
layout(location = 0) in vec3 a_pos;
layout(location = 1) in vec2 a_uv;
uniform mat4 u_clip_from_local;
uniform mat4 u_local_from_remote;
out vec2 v_uv;
invariant gl_Position;
void main() {
  v_uv = a_uv;
  gl_Position = u_clip_from_local * (u_local_from_remote * vec4(a_pos, 1.0));
}
)";
constexpr const char* kBakedFs = R"(#version 330 core
in vec2 v_uv;
uniform sampler2D u_atlas;
out vec4 o_color;
void main() { o_color = vec4(texture(u_atlas, v_uv).rgb, 1.0); }
)";

// One vertex of the baked mesh: a triangle corner and its atlas coordinate.
struct BakedVertex {
  float p[3];
  float uv[2];
};
static_assert(sizeof(BakedVertex) == 20);

GLint Loc(GLuint program, const char* name) { return glGetUniformLocation(program, name); }

void SetMat4(GLuint program, const char* name, const Eigen::Matrix4f& m) {
  glUniformMatrix4fv(Loc(program, name), 1, GL_FALSE, m.data());  // Eigen is column-major like GL
}

}  // namespace

const char* ColorModeName(ColorMode m) { return m == ColorMode::kVertexColor ? "vertex_color" : "projective"; }

Status ProjectiveOptions::Check() const {
  if (!(alpha >= 0 && alpha <= 64)) return InvalidArgument("projective alpha must be in [0, 64]");
  if (!(beta >= 0 && beta <= 64)) return InvalidArgument("projective beta must be in [0, 64]");
  if (!(visibility_tolerance_m > 0 && visibility_tolerance_m < 1)) {
    return InvalidArgument("visibility_tolerance_m must be in (0, 1)");
  }
  if (!(discontinuity_jump_m > 0)) return InvalidArgument("discontinuity_jump_m must be > 0");
  if (!(discontinuity_radius_m >= 0 && discontinuity_radius_m < 1)) {
    return InvalidArgument("discontinuity_radius_m must be in [0, 1)");
  }
  if (!(discontinuity_weight > 0 && discontinuity_weight <= 1)) {
    return InvalidArgument("discontinuity_weight must be in (0, 1]");
  }
  if (!(mask_erode_px >= 0 && mask_erode_px <= 32)) return InvalidArgument("mask_erode_px must be in [0, 32]");
  if (!(mask_feather_px >= 0 && mask_feather_px <= 32)) return InvalidArgument("mask_feather_px must be in [0, 32]");
  if (!(min_mask_confidence >= 0 && min_mask_confidence <= 1)) {
    return InvalidArgument("min_mask_confidence must be in [0, 1]");
  }
  if (!(edge_floor_weight > 0 && edge_floor_weight <= 1)) return InvalidArgument("edge_floor_weight must be in (0, 1]");
  if (pods_per_vertex < 0 || pods_per_vertex > Renderer::kMaxPods) {
    return InvalidArgument("pods_per_vertex must be in [0, " + std::to_string(Renderer::kMaxPods) + "]");
  }
  if (max_pods_per_triangle < 1 || max_pods_per_triangle > Renderer::kMaxPods) {
    return InvalidArgument("max_pods_per_triangle must be in [1, " + std::to_string(Renderer::kMaxPods) + "]");
  }
  if (bake_texels_per_edge < 1 || bake_texels_per_edge > 16) {
    return InvalidArgument("bake_texels_per_edge must be in [1, 16]");
  }
  if (!(bake_texels_per_pod_pixel >= 0 && bake_texels_per_pod_pixel <= 64)) {
    return InvalidArgument("bake_texels_per_pod_pixel must be in [0, 64]");
  }
  return OkStatus();
}

ProjectiveOptions ProjectiveOptions::Legacy() {
  ProjectiveOptions o;
  o.use_masks = false;
  o.cull_back_faces = true;
  o.pods_per_vertex = 0;
  o.gpu_visibility = true;
  o.bake = false;
  return o;
}

RenderSettings RenderSettings::Legacy() {
  RenderSettings s;
  s.cull_back_faces = true;
  s.depth_prepass = false;
  s.projective = ProjectiveOptions::Legacy();
  return s;
}

// ---------------------------------------------------------------- OffscreenTarget

OffscreenTarget::~OffscreenTarget() {
  if (fbo_) glDeleteFramebuffers(1, &fbo_);
  if (color_) glDeleteRenderbuffers(1, &color_);
  if (depth_) glDeleteRenderbuffers(1, &depth_);
}

StatusOr<std::unique_ptr<OffscreenTarget>> OffscreenTarget::Create(int width, int height) {
  GLint max_size = 0;
  glGetIntegerv(GL_MAX_RENDERBUFFER_SIZE, &max_size);
  if (width <= 0 || height <= 0 || width > max_size || height > max_size) {
    return InvalidArgument("render target " + std::to_string(width) + "x" + std::to_string(height) +
                           " outside 1.." + std::to_string(max_size));
  }
  std::unique_ptr<OffscreenTarget> t(new OffscreenTarget);
  t->width_ = width;
  t->height_ = height;
  glGenFramebuffers(1, &t->fbo_);
  glGenRenderbuffers(1, &t->color_);
  glGenRenderbuffers(1, &t->depth_);
  glBindRenderbuffer(GL_RENDERBUFFER, t->color_);
  glRenderbufferStorage(GL_RENDERBUFFER, GL_RGBA8, width, height);
  glBindRenderbuffer(GL_RENDERBUFFER, t->depth_);
  glRenderbufferStorage(GL_RENDERBUFFER, GL_DEPTH_COMPONENT24, width, height);
  glBindFramebuffer(GL_FRAMEBUFFER, t->fbo_);
  glFramebufferRenderbuffer(GL_FRAMEBUFFER, GL_COLOR_ATTACHMENT0, GL_RENDERBUFFER, t->color_);
  glFramebufferRenderbuffer(GL_FRAMEBUFFER, GL_DEPTH_ATTACHMENT, GL_RENDERBUFFER, t->depth_);
  if (glCheckFramebufferStatus(GL_FRAMEBUFFER) != GL_FRAMEBUFFER_COMPLETE) {
    return Internal("offscreen framebuffer is incomplete");
  }
  HOLO_RETURN_IF_ERROR(CheckGlError("OffscreenTarget::Create"));
  return t;
}

void OffscreenTarget::Bind() const {
  glBindFramebuffer(GL_FRAMEBUFFER, fbo_);
  glViewport(0, 0, width_, height_);
}

Status OffscreenTarget::ReadRgb(ImageRgb8* out) const {
  glBindFramebuffer(GL_FRAMEBUFFER, fbo_);
  return ReadViewportRgb({0, 0, width_, height_}, out);
}

Status ReadViewportRgb(const Viewport& vp, ImageRgb8* out) {
  if (vp.width <= 0 || vp.height <= 0) return InvalidArgument("empty viewport");
  out->Resize(vp.width, vp.height);
  std::vector<uint8_t> rows(static_cast<size_t>(vp.width) * vp.height * 3);
  glPixelStorei(GL_PACK_ALIGNMENT, 1);
  glReadPixels(vp.x, vp.y, vp.width, vp.height, GL_RGB, GL_UNSIGNED_BYTE, rows.data());
  const size_t stride = static_cast<size_t>(vp.width) * 3;
  for (int y = 0; y < vp.height; ++y) {
    std::memcpy(out->row(y), rows.data() + (vp.height - 1 - y) * stride, stride);
  }
  return CheckGlError("glReadPixels");
}

// ---------------------------------------------------------------- Renderer

Renderer::~Renderer() {
  FreeMesh(&remote_);
  FreeMesh(&local_);
  FreeMesh(&baked_);
  if (atlas_tex_) glDeleteTextures(1, &atlas_tex_);
  if (baked_program_) glDeleteProgram(baked_program_);
  for (unsigned p : draw_programs_) {
    if (p) glDeleteProgram(p);
  }
  if (remote_pods_vbo_) glDeleteBuffers(1, &remote_pods_vbo_);
  if (depth_program_) glDeleteProgram(depth_program_);
  if (pod_color_tex_) glDeleteTextures(1, &pod_color_tex_);
  if (pod_depth_tex_) glDeleteTextures(1, &pod_depth_tex_);
  if (pod_raw_tex_) glDeleteTextures(1, &pod_raw_tex_);
  if (edge_program_) glDeleteProgram(edge_program_);
  if (empty_vao_) glDeleteVertexArrays(1, &empty_vao_);
  if (pod_depth_rb_) glDeleteRenderbuffers(1, &pod_depth_rb_);
  if (pod_fbo_) glDeleteFramebuffers(1, &pod_fbo_);
}

StatusOr<std::unique_ptr<Renderer>> Renderer::Create() {
  std::unique_ptr<Renderer> r(new Renderer);
  HOLO_RETURN_IF_ERROR(r->Init());
  return r;
}

Status Renderer::Init() {
  GLint major = 0, minor = 0;
  glGetIntegerv(GL_MAJOR_VERSION, &major);
  glGetIntegerv(GL_MINOR_VERSION, &minor);
  if (major * 10 + minor < 33) {
    return Unavailable("the renderer needs OpenGL 3.3, the context has " + std::to_string(major) + "." +
                       std::to_string(minor));
  }
  const std::string depth_vs = std::string(kDepthVs) + kDistortGlsl;
  HOLO_RETURN_IF_ERROR(DrawProgram(0).status());
  HOLO_ASSIGN_OR_RETURN(depth_program_, BuildProgram("pod depth", depth_vs.c_str(), kDepthFs));
  HOLO_ASSIGN_OR_RETURN(edge_program_, BuildProgram("pod discontinuities", kEdgeVs, kEdgeFs));
  HOLO_ASSIGN_OR_RETURN(baked_program_, BuildProgram("baked atlas", kBakedVs, kBakedFs));
  glUseProgram(baked_program_);
  glUniform1i(Loc(baked_program_, "u_atlas"), 0);
  glUseProgram(0);
  glGenVertexArrays(1, &empty_vao_);
  // Meshes without per-vertex pod bits (the local mesh) read this constant:
  // every pod allowed.
  glVertexAttribI4ui(3, 0xFFFFu, 0, 0, 0);
  return CheckGlError("Renderer::Init");
}

StatusOr<unsigned> Renderer::DrawProgram(int slots) {
  if (slots < 0 || slots > kMaxPods) return InvalidArgument("no draw program for " + std::to_string(slots) + " pods");
  if (draw_programs_[slots]) return draw_programs_[slots];
  const std::string head = "#version 330 core\n#define SLOTS " + std::to_string(slots) + "\n";
  const std::string vs = head + kDrawVs;
  const std::string fs = head + kDrawFs + (slots > 0 ? kDistortGlsl : "");
  HOLO_ASSIGN_OR_RETURN(unsigned p, BuildProgram("mesh (" + std::to_string(slots) + " pods)", vs.c_str(), fs.c_str()));
  if (slots > 0) {
    glUseProgram(p);
    glUniform1i(Loc(p, "u_pod_color"), 0);
    glUniform1i(Loc(p, "u_pod_depth"), 1);
    glUseProgram(0);
  }
  draw_programs_[slots] = p;
  return p;
}

void Renderer::FreeMesh(GpuMesh* gpu) {
  if (gpu->vao) glDeleteVertexArrays(1, &gpu->vao);
  if (gpu->vbo) glDeleteBuffers(1, &gpu->vbo);
  if (gpu->ibo) glDeleteBuffers(1, &gpu->ibo);
  *gpu = GpuMesh{};
}

Status Renderer::Upload(const Mesh& mesh, GpuMesh* gpu, std::vector<Eigen::Vector3f>* normals) {
  HOLO_RETURN_IF_ERROR(mesh.Validate());
  if (mesh.num_vertices() > (1u << 30) || mesh.num_triangles() > (1u << 30)) {
    return InvalidArgument("mesh too large to draw: " + std::to_string(mesh.num_vertices()) + " vertices");
  }
  const Mesh* m = &mesh;
  Mesh with_normals;
  if (mesh.normals.size() != mesh.positions.size()) {
    with_normals = mesh;
    with_normals.ComputeNormals();
    m = &with_normals;
  }
  std::vector<GpuVertex> verts(m->num_vertices());
  const bool has_color = m->colors.size() == m->positions.size();
  for (size_t i = 0; i < verts.size(); ++i) {
    GpuVertex& v = verts[i];
    for (int k = 0; k < 3; ++k) {
      v.p[k] = m->positions[i][k];
      v.n[k] = m->normals[i][k];
      v.c[k] = has_color ? m->colors[i][k] : 180;
    }
    v.c[3] = 255;
  }
  if (!gpu->vao) {
    glGenVertexArrays(1, &gpu->vao);
    glGenBuffers(1, &gpu->vbo);
    glGenBuffers(1, &gpu->ibo);
    glBindVertexArray(gpu->vao);
    glBindBuffer(GL_ARRAY_BUFFER, gpu->vbo);
    glBindBuffer(GL_ELEMENT_ARRAY_BUFFER, gpu->ibo);
    glEnableVertexAttribArray(0);
    glVertexAttribPointer(0, 3, GL_FLOAT, GL_FALSE, sizeof(GpuVertex), reinterpret_cast<void*>(offsetof(GpuVertex, p)));
    glEnableVertexAttribArray(1);
    glVertexAttribPointer(1, 3, GL_FLOAT, GL_FALSE, sizeof(GpuVertex), reinterpret_cast<void*>(offsetof(GpuVertex, n)));
    glEnableVertexAttribArray(2);
    glVertexAttribPointer(2, 4, GL_UNSIGNED_BYTE, GL_TRUE, sizeof(GpuVertex),
                          reinterpret_cast<void*>(offsetof(GpuVertex, c)));
  }
  glBindVertexArray(gpu->vao);
  glBindBuffer(GL_ARRAY_BUFFER, gpu->vbo);
  const size_t vbytes = verts.size() * sizeof(GpuVertex);
  const size_t ibytes = m->triangles.size() * sizeof(m->triangles[0]);
  if (vbytes > gpu->vbo_bytes) {
    glBufferData(GL_ARRAY_BUFFER, static_cast<GLsizeiptr>(vbytes), verts.data(), GL_DYNAMIC_DRAW);
    gpu->vbo_bytes = vbytes;
  } else if (vbytes > 0) {
    glBufferSubData(GL_ARRAY_BUFFER, 0, static_cast<GLsizeiptr>(vbytes), verts.data());
  }
  if (ibytes > gpu->ibo_bytes) {
    glBufferData(GL_ELEMENT_ARRAY_BUFFER, static_cast<GLsizeiptr>(ibytes), m->triangles.data(), GL_DYNAMIC_DRAW);
    gpu->ibo_bytes = ibytes;
  } else if (ibytes > 0) {
    glBufferSubData(GL_ELEMENT_ARRAY_BUFFER, 0, static_cast<GLsizeiptr>(ibytes), m->triangles.data());
  }
  gpu->index_count = m->triangles.size() * 3;
  glBindVertexArray(0);
  if (normals) *normals = m->normals;
  return CheckGlError("mesh upload");
}

void Renderer::Draw(const GpuMesh& gpu) const {
  if (gpu.index_count == 0) return;
  glBindVertexArray(gpu.vao);
  glDrawElements(GL_TRIANGLES, static_cast<GLsizei>(gpu.index_count), GL_UNSIGNED_INT, nullptr);
  glBindVertexArray(0);
}

Status Renderer::SetRemoteMesh(const Mesh& mesh) {
  HOLO_RETURN_IF_ERROR(Upload(mesh, &remote_, &remote_normals_));
  remote_positions_ = mesh.positions;
  remote_triangles_ = mesh.triangles;
  // Per-vertex pod bits: every pod allowed until SelectPods chooses.
  const std::vector<uint16_t> all(mesh.num_vertices(), 0xFFFFu);
  if (!remote_pods_vbo_) glGenBuffers(1, &remote_pods_vbo_);
  glBindVertexArray(remote_.vao);
  glBindBuffer(GL_ARRAY_BUFFER, remote_pods_vbo_);
  const size_t bytes = all.size() * sizeof(uint16_t);
  if (bytes > remote_pods_vbo_bytes_) {
    glBufferData(GL_ARRAY_BUFFER, static_cast<GLsizeiptr>(bytes), all.data(), GL_DYNAMIC_DRAW);
    remote_pods_vbo_bytes_ = bytes;
  } else if (bytes > 0) {
    glBufferSubData(GL_ARRAY_BUFFER, 0, static_cast<GLsizeiptr>(bytes), all.data());
  }
  glEnableVertexAttribArray(3);
  glVertexAttribIPointer(3, 1, GL_UNSIGNED_SHORT, sizeof(uint16_t), nullptr);
  glBindVertexArray(0);
  pod_sets_.clear();
  selection_dirty_ = true;
  remote_has_colors_ = !mesh.colors.empty() && mesh.colors.size() == mesh.positions.size();
  if (remote_has_colors_) {
    remote_colors_ = mesh.colors;
  } else {
    remote_colors_.clear();
  }
  atlas_dirty_ = true;
  remote_min_ = Eigen::Vector3f::Constant(1e30f);
  remote_max_ = Eigen::Vector3f::Constant(-1e30f);
  for (const auto& p : mesh.positions) {
    remote_min_ = remote_min_.cwiseMin(p);
    remote_max_ = remote_max_.cwiseMax(p);
  }
  visibility_dirty_ = true;
  return OkStatus();
}

Status Renderer::SetLocalMesh(const Mesh& mesh) { return Upload(mesh, &local_); }

Status Renderer::SetPodImages(const Rig& rig, const std::vector<const ImageRgb8*>& images) {
  return SetPodImages(rig, images, {});
}

Status Renderer::SetPodImages(const Rig& rig, const std::vector<const ImageRgb8*>& images,
                              const std::vector<const ImageGray8*>& masks) {
  const int n = static_cast<int>(rig.pods.size());
  if (n == 0 || n > kMaxPods) {
    return InvalidArgument("projective texturing supports 1.." + std::to_string(kMaxPods) + " pods, rig has " +
                           std::to_string(n));
  }
  if (images.size() != rig.pods.size()) {
    return InvalidArgument("got " + std::to_string(images.size()) + " pod images for a rig of " + std::to_string(n) +
                           " pods");
  }
  int w = 0, h = 0;
  for (int i = 0; i < n; ++i) {
    const Intrinsics& c = rig.pods[i].color;
    HOLO_RETURN_IF_ERROR(c.Check().WithContext("pod " + std::to_string(i) + " colour camera"));
    if (images[i] == nullptr || images[i]->width() != c.width || images[i]->height() != c.height) {
      return InvalidArgument("pod " + std::to_string(i) + " image is " +
                             (images[i] ? std::to_string(images[i]->width()) + "x" + std::to_string(images[i]->height())
                                        : std::string("missing")) +
                             ", its colour camera is " + std::to_string(c.width) + "x" + std::to_string(c.height));
    }
    if (!masks.empty() && (masks.size() != images.size() || masks[i] == nullptr ||
                           masks[i]->width() != c.width || masks[i]->height() != c.height)) {
      return InvalidArgument("pod " + std::to_string(i) + " mask is " +
                             (masks.size() == images.size() && masks[i]
                                  ? std::to_string(masks[i]->width()) + "x" + std::to_string(masks[i]->height())
                                  : std::string("missing")) +
                             ", its image is " + std::to_string(c.width) + "x" + std::to_string(c.height));
    }
    w = std::max(w, c.width);
    h = std::max(h, c.height);
  }
  GLint max_size = 0;
  glGetIntegerv(GL_MAX_TEXTURE_SIZE, &max_size);
  if (w > max_size || h > max_size) return InvalidArgument("pod images larger than GL_MAX_TEXTURE_SIZE");
  if (!pod_color_tex_) {
    glGenTextures(1, &pod_color_tex_);
    glGenTextures(1, &pod_depth_tex_);
    glGenTextures(1, &pod_raw_tex_);
    glGenRenderbuffers(1, &pod_depth_rb_);
    glGenFramebuffers(1, &pod_fbo_);
  }
  if (n != num_pods_ || w != array_width_ || h != array_height_) {
    glBindTexture(GL_TEXTURE_2D_ARRAY, pod_color_tex_);
    glTexImage3D(GL_TEXTURE_2D_ARRAY, 0, GL_RGBA8, w, h, n, 0, GL_RGBA, GL_UNSIGNED_BYTE, nullptr);
    glTexParameteri(GL_TEXTURE_2D_ARRAY, GL_TEXTURE_MIN_FILTER, GL_LINEAR);
    glTexParameteri(GL_TEXTURE_2D_ARRAY, GL_TEXTURE_MAG_FILTER, GL_LINEAR);
    glTexParameteri(GL_TEXTURE_2D_ARRAY, GL_TEXTURE_WRAP_S, GL_CLAMP_TO_EDGE);
    glTexParameteri(GL_TEXTURE_2D_ARRAY, GL_TEXTURE_WRAP_T, GL_CLAMP_TO_EDGE);
    for (GLuint tex : {pod_depth_tex_, pod_raw_tex_}) {
      glBindTexture(GL_TEXTURE_2D_ARRAY, tex);
      glTexImage3D(GL_TEXTURE_2D_ARRAY, 0, GL_R32F, w, h, n, 0, GL_RED, GL_FLOAT, nullptr);
      glTexParameteri(GL_TEXTURE_2D_ARRAY, GL_TEXTURE_MIN_FILTER, GL_NEAREST);
      glTexParameteri(GL_TEXTURE_2D_ARRAY, GL_TEXTURE_MAG_FILTER, GL_NEAREST);
    }
    glBindRenderbuffer(GL_RENDERBUFFER, pod_depth_rb_);
    glRenderbufferStorage(GL_RENDERBUFFER, GL_DEPTH_COMPONENT24, w, h);
    num_pods_ = n;
    array_width_ = w;
    array_height_ = h;
  }
  pod_images_.resize(n);
  for (int i = 0; i < n; ++i) pod_images_[i] = *images[i];
  pod_masks_.resize(masks.size());
  for (size_t i = 0; i < masks.size(); ++i) pod_masks_[i] = *masks[i];
  textures_dirty_ = true;
  std::vector<CameraModel> cams;
  for (const auto& pod : rig.pods) cams.push_back(pod.ColorCamera());
  bool same_cams = cams.size() == pod_cameras_.size();
  for (size_t i = 0; same_cams && i < cams.size(); ++i) {
    same_cams = cams[i].world_from_camera.matrix() == pod_cameras_[i].world_from_camera.matrix() &&
                cams[i].intrinsics.fx == pod_cameras_[i].intrinsics.fx &&
                cams[i].intrinsics.cx == pod_cameras_[i].intrinsics.cx &&
                cams[i].intrinsics.cy == pod_cameras_[i].intrinsics.cy &&
                cams[i].intrinsics.fy == pod_cameras_[i].intrinsics.fy &&
                cams[i].intrinsics.distortion == pod_cameras_[i].intrinsics.distortion &&
                cams[i].intrinsics.width == pod_cameras_[i].intrinsics.width &&
                cams[i].intrinsics.height == pod_cameras_[i].intrinsics.height;
  }
  if (!same_cams) {
    pod_cameras_ = std::move(cams);
    visibility_dirty_ = true;
  }
  return CheckGlError("SetPodImages");
}

Status Renderer::UpdateVisibilityCpu(const ProjectiveOptions& options) {
  const int n = num_pods_;
  while (static_cast<int>(pod_rasters_.size()) < n) pod_rasters_.push_back(std::make_unique<MeshRasterizer>());
  pod_raw_z_.resize(n);
  pod_flagged_z_.resize(n);
  const float jump = options.discontinuity_jump_m, radius = options.discontinuity_radius_m;
  // Pods in parallel (each has its own rasterizer and maps), uploads after.
  if (!pool_) pool_ = std::make_unique<WorkerPool>(ResolveThreadCount(0));
  pool_->ParallelFor(n, [&](int i) {
    const CameraModel& cam = pod_cameras_[i];
    const int w = cam.intrinsics.width, h = cam.intrinsics.height;
    MeshRasterizer& raster = *pod_rasters_[i];
    raster.Rasterize(remote_positions_, remote_triangles_, cam, /*want_attributes=*/false, options.cull_back_faces,
                     0.05f);
    const std::vector<float>& iz = raster.inv_z();
    std::vector<float>& raw = pod_raw_z_[i];
    std::vector<float>& flagged = pod_flagged_z_[i];
    raw.assign(static_cast<size_t>(w) * h, 0.0f);
    flagged.assign(raw.size(), 0.0f);
    const int x0 = raster.box_x0(), y0 = raster.box_y0(), x1 = raster.box_x1(), y1 = raster.box_y1();
    for (int y = y0; y <= y1; ++y) {
      for (int x = x0; x <= x1; ++x) {
        const size_t k = static_cast<size_t>(y) * w + x;
        if (iz[k] > 0.0f) raw[k] = 1.0f / iz[k];
      }
    }
    // Discontinuity flags as the GL pass (kEdgeFs) computes them: a
    // neighbour at the radius (discontinuity_radius_m at this depth, 1..8
    // px, clamped to the image) empty or more than the jump away.
    static constexpr int kOffsets[8][2] = {{-1, 0}, {1, 0}, {0, -1}, {0, 1}, {-1, -1}, {1, 1}, {-1, 1}, {1, -1}};
    const float fx = static_cast<float>(cam.intrinsics.fx);
    for (int y = y0; y <= y1; ++y) {
      for (int x = x0; x <= x1; ++x) {
        const size_t k = static_cast<size_t>(y) * w + x;
        const float z = raw[k];
        if (z <= 0.0f) continue;
        const int r = std::clamp(static_cast<int>(std::ceil(radius * fx / z)), 1, 8);
        bool edge = false;
        for (const auto& o : kOffsets) {
          const int xx = std::clamp(x + o[0] * r, 0, w - 1), yy = std::clamp(y + o[1] * r, 0, h - 1);
          const float zq = raw[static_cast<size_t>(yy) * w + xx];
          edge |= zq <= 0.0f || std::abs(zq - z) > jump;
        }
        flagged[k] = edge ? -z : z;
      }
    }
  });
  // The GL copies are made only when the per-fragment path draws with them
  // (SyncPodTexturesToGpu): the baked atlas reads these CPU maps.
  depth_tex_stale_ = true;
  edge_jump_m_ = jump;
  edge_radius_m_ = radius;
  vis_gpu_ = false;
  vis_cull_ = options.cull_back_faces;
  visibility_dirty_ = false;
  selection_dirty_ = true;
  flagged_on_cpu_ = true;
  return CheckGlError("pod visibility maps (CPU)");
}

Status Renderer::UpdateVisibility(const ProjectiveOptions& options) {
  HOLO_RETURN_IF_ERROR(options.Check());
  if (num_pods_ == 0) return InvalidArgument("no pod images: call SetPodImages before projective texturing");
  if (!options.gpu_visibility) return UpdateVisibilityCpu(options);
  constexpr float kNear = 0.05f, kFar = 100.0f;
  GLint old_fbo = 0;
  glGetIntegerv(GL_DRAW_FRAMEBUFFER_BINDING, &old_fbo);
  glBindFramebuffer(GL_FRAMEBUFFER, pod_fbo_);
  glFramebufferRenderbuffer(GL_FRAMEBUFFER, GL_DEPTH_ATTACHMENT, GL_RENDERBUFFER, pod_depth_rb_);
  glUseProgram(depth_program_);
  glUniform1f(Loc(depth_program_, "u_near"), kNear);
  glUniform1f(Loc(depth_program_, "u_far"), kFar);
  glDisable(GL_SCISSOR_TEST);
  if (options.cull_back_faces) {
    // The pod pass does not flip y (texel row v = image row v), so the
    // outside of a counter-clockwise triangle appears clockwise.
    glFrontFace(GL_CW);
    glCullFace(GL_BACK);
    glEnable(GL_CULL_FACE);
  } else {
    glDisable(GL_CULL_FACE);
  }
  glEnable(GL_DEPTH_TEST);
  glDepthFunc(GL_LESS);
  glDepthMask(GL_TRUE);
  glColorMask(GL_TRUE, GL_TRUE, GL_TRUE, GL_TRUE);
  for (int i = 0; i < num_pods_; ++i) {
    glFramebufferTextureLayer(GL_FRAMEBUFFER, GL_COLOR_ATTACHMENT0, pod_raw_tex_, 0, i);
    if (glCheckFramebufferStatus(GL_FRAMEBUFFER) != GL_FRAMEBUFFER_COMPLETE) {
      glBindFramebuffer(GL_FRAMEBUFFER, static_cast<GLuint>(old_fbo));
      return Internal("pod depth framebuffer is incomplete");
    }
    glViewport(0, 0, array_width_, array_height_);
    glClearColor(0, 0, 0, 0);
    glClearDepth(1.0);
    glClear(GL_COLOR_BUFFER_BIT | GL_DEPTH_BUFFER_BIT);
    const CameraModel& cam = pod_cameras_[i];
    const Intrinsics& in = cam.intrinsics;
    glViewport(0, 0, in.width, in.height);
    SetMat4(depth_program_, "u_cam_from_world", cam.world_from_camera.inverse().matrix());
    glUniform4f(Loc(depth_program_, "u_intr"), static_cast<float>(in.fx), static_cast<float>(in.fy),
                static_cast<float>(in.cx), static_cast<float>(in.cy));
    glUniform4f(Loc(depth_program_, "u_dist"), static_cast<float>(in.distortion[0]),
                static_cast<float>(in.distortion[1]), static_cast<float>(in.distortion[2]),
                static_cast<float>(in.distortion[3]));
    glUniform1f(Loc(depth_program_, "u_k3"), static_cast<float>(in.distortion[4]));
    glUniform2f(Loc(depth_program_, "u_size"), static_cast<float>(in.width), static_cast<float>(in.height));
    Draw(remote_);
  }
  glDisable(GL_CULL_FACE);
  glFrontFace(GL_CCW);
  // Discontinuity flags into pod_depth_tex_.
  glDisable(GL_DEPTH_TEST);
  glUseProgram(edge_program_);
  glUniform1i(Loc(edge_program_, "u_depth"), 0);
  glUniform1f(Loc(edge_program_, "u_jump"), options.discontinuity_jump_m);
  glUniform1f(Loc(edge_program_, "u_radius"), options.discontinuity_radius_m);
  glActiveTexture(GL_TEXTURE0);
  glBindTexture(GL_TEXTURE_2D_ARRAY, pod_raw_tex_);
  glBindVertexArray(empty_vao_);
  for (int i = 0; i < num_pods_; ++i) {
    glFramebufferTextureLayer(GL_FRAMEBUFFER, GL_COLOR_ATTACHMENT0, pod_depth_tex_, 0, i);
    const Intrinsics& in = pod_cameras_[i].intrinsics;
    glViewport(0, 0, array_width_, array_height_);
    glClearColor(0, 0, 0, 0);
    glClear(GL_COLOR_BUFFER_BIT);
    glViewport(0, 0, in.width, in.height);
    // Only the pixels the mesh can cover (its bounding box projected, plus
    // the largest radius): most of a pod's image is empty.
    int box[4] = {0, 0, in.width, in.height};
    PodBox(pod_cameras_[i], box);
    glEnable(GL_SCISSOR_TEST);
    glScissor(box[0], box[1], box[2], box[3]);
    glUniform1i(Loc(edge_program_, "u_layer"), i);
    glUniform2f(Loc(edge_program_, "u_size"), static_cast<float>(in.width), static_cast<float>(in.height));
    glUniform1f(Loc(edge_program_, "u_fx"), static_cast<float>(in.fx));
    glDrawArrays(GL_TRIANGLES, 0, 3);
    glDisable(GL_SCISSOR_TEST);
  }
  glBindVertexArray(0);
  glBindTexture(GL_TEXTURE_2D_ARRAY, 0);
  glEnable(GL_DEPTH_TEST);
  glUseProgram(0);
  glBindFramebuffer(GL_FRAMEBUFFER, static_cast<GLuint>(old_fbo));
  edge_jump_m_ = options.discontinuity_jump_m;
  edge_radius_m_ = options.discontinuity_radius_m;
  vis_gpu_ = true;
  vis_cull_ = options.cull_back_faces;
  visibility_dirty_ = false;
  selection_dirty_ = true;
  flagged_on_cpu_ = false;
  depth_tex_stale_ = false;
  return CheckGlError("pod visibility pass");
}

void Renderer::MakePodRgba(const ProjectiveOptions& options) {
  const bool use_masks = options.use_masks && !pod_masks_.empty();
  pod_alpha_.assign(use_masks ? num_pods_ : 0, {});
  for (int i = 0; i < num_pods_; ++i) {
    const ImageRgb8& img = pod_images_[i];
    const int w = img.width(), h = img.height();
    const size_t npx = static_cast<size_t>(w) * h;
    pod_rgba_.resize(num_pods_);
    pod_rgba_[i].resize(npx * 4);
    uint8_t* out = pod_rgba_[i].data();
    const uint8_t* in = img.data();
    if (!use_masks) {
      for (size_t k = 0; k < npx; ++k) {
        out[4 * k + 0] = in[3 * k + 0];
        out[4 * k + 1] = in[3 * k + 1];
        out[4 * k + 2] = in[3 * k + 2];
        out[4 * k + 3] = 255;
      }
    } else {
      // Chessboard distance of every mask pixel to the nearest background
      // pixel (or the image border), two passes, capped at 255. Only the
      // mask's bounding box can be nonzero: the passes run over it, and
      // everything outside (background) is zero.
      const uint8_t* m = pod_masks_[i].data();
      int bx0 = w, by0 = h, bx1 = -1, by1 = -1;
      for (int y = 0; y < h; ++y) {
        const uint8_t* row = m + static_cast<size_t>(y) * w;
        int first = 0;
        while (first < w && row[first] == 0) ++first;
        if (first == w) continue;
        int last = w - 1;
        while (row[last] == 0) --last;
        bx0 = std::min(bx0, first);
        bx1 = std::max(bx1, last);
        by0 = std::min(by0, y);
        by1 = y;
      }
      dist_scratch_.assign(npx, 0);
      uint8_t* d = dist_scratch_.data();
      for (int y = by0; y <= by1; ++y) {
        for (int x = bx0; x <= bx1; ++x) {
          const size_t k = static_cast<size_t>(y) * w + x;
          if (m[k] == 0) continue;
          int v = 1;  // the image border counts as background
          if (x > 0 && y > 0) {
            v = std::min({d[k - 1], d[k - w], d[k - w - 1], x + 1 < w ? d[k - w + 1] : uint8_t{0}}) + 1;
          }
          d[k] = static_cast<uint8_t>(std::min(v, 255));
        }
      }
      for (int y = by1; y >= by0; --y) {
        for (int x = bx1; x >= bx0; --x) {
          const size_t k = static_cast<size_t>(y) * w + x;
          if (d[k] == 0) continue;
          int v = 1;
          if (x + 1 < w && y + 1 < h) {
            v = std::min({d[k + 1], d[k + w], d[k + w + 1], x > 0 ? d[k + w - 1] : uint8_t{0}}) + 1;
          }
          d[k] = static_cast<uint8_t>(std::min<int>(d[k], v));
        }
      }
      // Weight per distance, premultiplied into the colour so that bilinear
      // sampling never mixes in background texels.
      uint8_t lut[256];
      for (int k = 0; k < 256; ++k) {
        float wgt = 0.0f;
        if (k > 0) {
          const float ramp = options.mask_feather_px > 0
                                 ? (static_cast<float>(k) - options.mask_erode_px) / options.mask_feather_px
                                 : (static_cast<float>(k) > options.mask_erode_px ? 1.0f : 0.0f);
          wgt = std::clamp(ramp, options.edge_floor_weight, 1.0f);
        }
        lut[k] = static_cast<uint8_t>(std::lround(wgt * 255.0f));
        if (k > 0 && lut[k] == 0) lut[k] = 1;
      }
      std::fill(out, out + 4 * npx, uint8_t{0});  // lut[0] = 0: background is zero
      for (int y = by0; y <= by1; ++y) {
        for (int x = bx0; x <= bx1; ++x) {
          const size_t k = static_cast<size_t>(y) * w + x;
          const unsigned a = lut[d[k]];
          out[4 * k + 0] = static_cast<uint8_t>((in[3 * k + 0] * a + 127) / 255);
          out[4 * k + 1] = static_cast<uint8_t>((in[3 * k + 1] * a + 127) / 255);
          out[4 * k + 2] = static_cast<uint8_t>((in[3 * k + 2] * a + 127) / 255);
          out[4 * k + 3] = static_cast<uint8_t>(a);
        }
      }
      std::vector<uint8_t>& alpha = pod_alpha_[i];
      alpha.resize(npx);
      for (size_t k = 0; k < npx; ++k) alpha[k] = lut[d[k]];
    }
  }
  // Uploaded when the per-fragment path needs them (SyncPodTexturesToGpu).
  color_tex_stale_ = true;
  tex_use_masks_ = options.use_masks;
  tex_erode_ = options.mask_erode_px;
  tex_feather_ = options.mask_feather_px;
  tex_floor_ = options.edge_floor_weight;
  textures_dirty_ = false;
  selection_dirty_ = true;
}

Status Renderer::SyncPodTexturesToGpu() {
  if (color_tex_stale_) {
    glBindTexture(GL_TEXTURE_2D_ARRAY, pod_color_tex_);
    glPixelStorei(GL_UNPACK_ALIGNMENT, 1);
    for (int i = 0; i < num_pods_ && i < static_cast<int>(pod_rgba_.size()); ++i) {
      const Intrinsics& in = pod_cameras_[i].intrinsics;
      glTexSubImage3D(GL_TEXTURE_2D_ARRAY, 0, 0, 0, i, in.width, in.height, 1, GL_RGBA, GL_UNSIGNED_BYTE,
                      pod_rgba_[i].data());
    }
    color_tex_stale_ = false;
  }
  if (depth_tex_stale_) {
    glPixelStorei(GL_UNPACK_ALIGNMENT, 4);
    for (const auto& [tex, maps] : {std::pair{pod_raw_tex_, &pod_raw_z_}, std::pair{pod_depth_tex_, &pod_flagged_z_}}) {
      glBindTexture(GL_TEXTURE_2D_ARRAY, tex);
      for (int i = 0; i < num_pods_ && i < static_cast<int>(maps->size()); ++i) {
        const Intrinsics& in = pod_cameras_[i].intrinsics;
        glTexSubImage3D(GL_TEXTURE_2D_ARRAY, 0, 0, 0, i, in.width, in.height, 1, GL_RED, GL_FLOAT,
                        (*maps)[i].data());
      }
    }
    depth_tex_stale_ = false;
  }
  glBindTexture(GL_TEXTURE_2D_ARRAY, 0);
  return CheckGlError("pod textures upload");
}

Status Renderer::SelectPods(const ProjectiveOptions& options) {
  Stopwatch sw;
  const double cpu0 = ThreadCpuTimeMs();
  const int n = num_pods_;
  const size_t nv = remote_positions_.size();
  const size_t nt = remote_triangles_.size();
  std::vector<uint16_t> vertex_pods(nv, 0xFFFFu);
  triangle_pods_.assign(nt, 0);
  std::vector<std::array<uint32_t, 3>> ordered;
  pod_sets_.clear();
  selection_stats_ = {};
  const bool select = options.pods_per_vertex > 0 &&
                      !(options.pods_per_vertex >= n && options.max_pods_per_triangle >= n);
  if (!select) {
    // Every pod everywhere: one draw call over the mesh as it came.
    PodSet all;
    for (int i = 0; i < n; ++i) all.pods[i] = i;
    all.num_pods = n;
    all.index_count = nt * 3;
    pod_sets_.push_back(all);
    ordered = remote_triangles_;
    selection_stats_.mean_pods = n;
  } else {
    // The flagged depth maps of the visibility pass (camera z, negative
    // near a discontinuity): the CPU pass's, or read back once per mesh.
    HOLO_RETURN_IF_ERROR(FlaggedDepthOnCpu());
    const std::vector<std::vector<float>>& depth = pod_flagged_z_;
    // Per pod: camera from world, and without distortion the pixel
    // projection folded into one 3×4 matrix (rows: u·z, v·z, z).
    std::vector<Eigen::Matrix<float, 3, 4>> projection(n);
    std::vector<bool> distorted(n);
    for (int i = 0; i < n; ++i) {
      distorted[i] = pod_cameras_[i].intrinsics.HasDistortion();
      projection[i] = PodProjection(pod_cameras_[i]);
    }
    // The view-independent weight of every (vertex, pod), as the shaders
    // would give it: facing term, visibility, discontinuity and mask weight.
    // The vertex test is lenient (twice the tolerance, best of a 3×3
    // neighbourhood): it only chooses pods; fragments still test exactly.
    const float tol = 2.0f * options.visibility_tolerance_m;
    const bool masks = !pod_alpha_.empty();
    std::vector<float> weight(nv * n, 0.0f);
    // Pod by pod (one depth map and mask stay in cache), pods in parallel.
    if (!pool_) pool_ = std::make_unique<WorkerPool>(ResolveThreadCount(0));
    pool_->ParallelFor(n, [&](int i) {
      const CameraModel& cam = pod_cameras_[i];
      const Eigen::Vector3f center = cam.Center();
      for (size_t v = 0; v < nv; ++v) {
        const Eigen::Vector3f& p = remote_positions_[v];
        const Eigen::Vector3f& nrm = remote_normals_[v];
        const Eigen::Vector3f to_pod = center - p;
        const float dot = nrm.dot(to_pod);
        if (!(dot > 0)) continue;  // facing away (about half): no square roots
        const float len = to_pod.norm();
        if (!(len > 0)) continue;
        const float ndv = dot / (len * std::max(nrm.norm(), 1e-12f));
        if (!(ndv > 0)) continue;
        const Eigen::Vector3f pc = projection[i] * p.homogeneous();  // camera point, or pixel·z
        if (pc.z() < 0.05f) continue;
        Eigen::Vector2f px = pc.head<2>() / pc.z();
        if (distorted[i] && !cam.ProjectCamera(pc, &px)) continue;
        const int w = cam.intrinsics.width, h = cam.intrinsics.height;
        const int x = static_cast<int>(std::floor(px.x() + 0.5f)), y = static_cast<int>(std::floor(px.y() + 0.5f));
        if (x < 0 || y < 0 || x >= w || y >= h) continue;
        float best = 0.0f, best_err = 1e30f;  // flagged depth of the best texel (0 = none)
        for (int dy = -1; dy <= 1; ++dy) {
          for (int dx = -1; dx <= 1; ++dx) {
            const int xx = x + dx, yy = y + dy;
            if (xx < 0 || yy < 0 || xx >= w || yy >= h) continue;
            const float zf = depth[i][static_cast<size_t>(yy) * w + xx];
            const float err = std::abs(std::abs(zf) - pc.z());
            if (zf != 0.0f && err < best_err) {
              best_err = err;
              best = zf;
            }
          }
        }
        if (best == 0.0f || pc.z() > std::abs(best) + tol) continue;
        float wgt = options.alpha == 2.0f ? ndv * ndv : std::pow(ndv, options.alpha);
        if (best < 0.0f) wgt *= options.discontinuity_weight;
        if (masks) wgt *= pod_alpha_[i][static_cast<size_t>(y) * w + x] / 255.0f;
        weight[v * n + i] = wgt;
      }
    });
    // Each vertex keeps its `pods_per_vertex` best pods.
    const int keep = std::min(options.pods_per_vertex, n);
    std::array<int, kMaxPods> order{};
    for (size_t v = 0; v < nv; ++v) {
      const float* wv = &weight[v * n];
      for (int i = 0; i < n; ++i) order[i] = i;
      std::partial_sort(order.begin(), order.begin() + keep, order.begin() + n,
                        [&](int a, int b) { return wv[a] > wv[b] || (wv[a] == wv[b] && a < b); });
      uint16_t bits = 0;
      for (int k = 0; k < keep; ++k) {
        if (wv[order[k]] > 0.0f) bits = static_cast<uint16_t>(bits | (1u << order[k]));
      }
      vertex_pods[v] = bits;
    }
    // Each triangle: the union of its vertices' pods, capped.
    std::vector<std::pair<uint16_t, uint32_t>> keyed(nt);
    size_t slots = 0;
    for (size_t t = 0; t < nt; ++t) {
      const auto& tri = remote_triangles_[t];
      uint16_t bits = static_cast<uint16_t>(vertex_pods[tri[0]] | vertex_pods[tri[1]] | vertex_pods[tri[2]]);
      int count = std::popcount(bits);
      if (count > options.max_pods_per_triangle) {
        ++selection_stats_.capped_triangles;
        std::array<float, kMaxPods> sum{};
        int m = 0;
        for (int i = 0; i < n; ++i) {
          if (bits & (1u << i)) {
            order[m++] = i;
            sum[i] = weight[tri[0] * n + i] + weight[tri[1] * n + i] + weight[tri[2] * n + i];
          }
        }
        std::partial_sort(order.begin(), order.begin() + options.max_pods_per_triangle, order.begin() + m,
                          [&](int a, int b) { return sum[a] > sum[b] || (sum[a] == sum[b] && a < b); });
        bits = 0;
        for (int k = 0; k < options.max_pods_per_triangle; ++k) bits = static_cast<uint16_t>(bits | (1u << order[k]));
        count = options.max_pods_per_triangle;
      }
      if (count == 0) ++selection_stats_.uncoloured_triangles;
      slots += static_cast<size_t>(count);
      triangle_pods_[t] = bits;
      keyed[t] = {bits, static_cast<uint32_t>(t)};
    }
    // Sorted by pod set, then triangle (the order std::sort of the pairs
    // gives): a stable radix sort over the 16-bit set, low byte then high.
    {
      std::vector<std::pair<uint16_t, uint32_t>> tmp(nt);
      for (int shift : {0, 8}) {
        std::array<size_t, 257> start{};
        for (const auto& k : keyed) ++start[((k.first >> shift) & 0xFF) + 1];
        for (int b = 0; b < 256; ++b) start[b + 1] += start[b];
        for (const auto& k : keyed) tmp[start[(k.first >> shift) & 0xFF]++] = k;
        keyed.swap(tmp);
      }
    }
    ordered.resize(nt);
    for (size_t t = 0; t < nt; ++t) {
      ordered[t] = remote_triangles_[keyed[t].second];
      if (t == 0 || keyed[t].first != keyed[t - 1].first) {
        PodSet set;
        for (int i = 0; i < n; ++i) {
          if (keyed[t].first & (1u << i)) set.pods[set.num_pods++] = i;
        }
        set.first_index = t * 3;
        pod_sets_.push_back(set);
      }
      pod_sets_.back().index_count += 3;
    }
    selection_stats_.mean_pods = nt ? static_cast<double>(slots) / static_cast<double>(nt) : 0.0;
  }
  vertex_pods_ = vertex_pods;
  if (!select) {
    const uint16_t all_bits = static_cast<uint16_t>((1u << n) - 1u);
    vertex_pods_.assign(nv, all_bits);
    triangle_pods_.assign(nt, all_bits);
  }
  atlas_dirty_ = true;
  glBindVertexArray(remote_.vao);
  glBindBuffer(GL_ARRAY_BUFFER, remote_pods_vbo_);
  if (nv > 0) glBufferSubData(GL_ARRAY_BUFFER, 0, static_cast<GLsizeiptr>(nv * sizeof(uint16_t)), vertex_pods.data());
  if (nt > 0) {
    glBufferSubData(GL_ELEMENT_ARRAY_BUFFER, 0, static_cast<GLsizeiptr>(nt * sizeof(ordered[0])), ordered.data());
  }
  glBindVertexArray(0);
  selection_stats_.draws = pod_sets_.size();
  sel_per_vertex_ = options.pods_per_vertex;
  sel_per_triangle_ = options.max_pods_per_triangle;
  sel_alpha_ = options.alpha;
  selection_dirty_ = false;
  selection_stats_.select_ms = sw.ElapsedMs();
  selection_stats_.select_cpu_ms = ThreadCpuTimeMs() - cpu0;
  return CheckGlError("pod selection");
}

Status Renderer::FlaggedDepthOnCpu() {
  if (flagged_on_cpu_) return OkStatus();
  const int n = num_pods_;
  pod_flagged_z_.resize(n);
  GLint old_fbo = 0;
  glGetIntegerv(GL_READ_FRAMEBUFFER_BINDING, &old_fbo);
  glBindFramebuffer(GL_READ_FRAMEBUFFER, pod_fbo_);
  glPixelStorei(GL_PACK_ALIGNMENT, 4);
  for (int i = 0; i < n; ++i) {
    const Intrinsics& in = pod_cameras_[i].intrinsics;
    pod_flagged_z_[i].resize(static_cast<size_t>(in.width) * in.height);
    glFramebufferTextureLayer(GL_READ_FRAMEBUFFER, GL_COLOR_ATTACHMENT0, pod_depth_tex_, 0, i);
    glReadPixels(0, 0, in.width, in.height, GL_RED, GL_FLOAT, pod_flagged_z_[i].data());
  }
  glBindFramebuffer(GL_READ_FRAMEBUFFER, static_cast<GLuint>(old_fbo));
  HOLO_RETURN_IF_ERROR(CheckGlError("pod depth readback"));
  flagged_on_cpu_ = true;
  return OkStatus();
}

bool Renderer::VisibilityCurrent(const ProjectiveOptions& options) const {
  return !visibility_dirty_ && options.discontinuity_jump_m == edge_jump_m_ &&
         options.discontinuity_radius_m == edge_radius_m_ && options.gpu_visibility == vis_gpu_ &&
         options.cull_back_faces == vis_cull_;
}

bool Renderer::TexturesCurrent(const ProjectiveOptions& options) const {
  return !textures_dirty_ && options.use_masks == tex_use_masks_ && options.mask_erode_px == tex_erode_ &&
         options.mask_feather_px == tex_feather_ && options.edge_floor_weight == tex_floor_;
}

bool Renderer::SelectionCurrent(const ProjectiveOptions& options) const {
  return !selection_dirty_ && options.pods_per_vertex == sel_per_vertex_ &&
         options.max_pods_per_triangle == sel_per_triangle_ && options.alpha == sel_alpha_;
}

Status Renderer::PreparePods(const ProjectiveOptions& options) {
  HOLO_RETURN_IF_ERROR(options.Check());
  if (num_pods_ == 0) return InvalidArgument("projective texturing needs the pods' images (SetPodImages)");
  if (!VisibilityCurrent(options)) HOLO_RETURN_IF_ERROR(UpdateVisibility(options));
  if (!TexturesCurrent(options)) MakePodRgba(options);
  if (!SelectionCurrent(options)) HOLO_RETURN_IF_ERROR(SelectPods(options));
  return OkStatus();
}

bool Renderer::AtlasCurrent(const ProjectiveOptions& options) const {
  return VisibilityCurrent(options) && TexturesCurrent(options) && SelectionCurrent(options) && !atlas_dirty_ &&
         atlas_texels_ == options.bake_texels_per_edge &&
         atlas_density_ == options.bake_texels_per_pod_pixel &&
         atlas_tol_ == options.visibility_tolerance_m && atlas_edge_ == options.discontinuity_weight &&
         atlas_conf_ == options.min_mask_confidence;
}

Status Renderer::UpdateAtlas(const ProjectiveOptions& options) {
  HOLO_RETURN_IF_ERROR(PreparePods(options));
  HOLO_RETURN_IF_ERROR(FlaggedDepthOnCpu());
  Stopwatch sw;
  if (!pool_) pool_ = std::make_unique<WorkerPool>(ResolveThreadCount(0));
  std::vector<AtlasPod> pods(num_pods_);
  for (int i = 0; i < num_pods_; ++i) {
    pods[i].camera = &pod_cameras_[i];
    pods[i].flagged_z = pod_flagged_z_[i].data();
    pods[i].rgba = pod_rgba_[i].data();
  }
  AtlasMeshInput in;
  in.positions = &remote_positions_;
  in.normals = &remote_normals_;
  in.colors = &remote_colors_;
  in.triangles = &remote_triangles_;
  in.vertex_pods = &vertex_pods_;
  in.triangle_pods = &triangle_pods_;
  AtlasBakeOptions bo;
  bo.texels_per_edge = options.bake_texels_per_edge;
  bo.texels_per_pod_pixel = options.bake_texels_per_pod_pixel;
  GLint max_size = 0;
  glGetIntegerv(GL_MAX_TEXTURE_SIZE, &max_size);
  bo.max_width = std::min(2048, static_cast<int>(max_size));
  bo.max_height = static_cast<int>(max_size);
  bo.alpha = options.alpha;
  bo.visibility_tolerance_m = options.visibility_tolerance_m;
  bo.discontinuity_weight = options.discontinuity_weight;
  bo.min_mask_confidence =
      options.use_masks && !pod_masks_.empty() && remote_has_colors_ ? options.min_mask_confidence : 0.0f;
  Atlas atlas;
  atlas_stats_ = {};
  const Status baked = BakeAtlas(in, pods, bo, pool_.get(), &atlas);
  atlas_stats_.texels_per_edge = atlas.texels_per_edge;
  atlas_texels_ = options.bake_texels_per_edge;
  atlas_density_ = options.bake_texels_per_pod_pixel;
  atlas_tol_ = options.visibility_tolerance_m;
  atlas_edge_ = options.discontinuity_weight;
  atlas_conf_ = options.min_mask_confidence;
  atlas_dirty_ = false;
  if (baked.code() == StatusCode::kOutOfRange) {
    // Too many triangles for one atlas texture: per-fragment blending.
    atlas_stats_.fallback = true;
    baked_vertices_ = 0;
    return OkStatus();
  }
  HOLO_RETURN_IF_ERROR(baked);
  if (!atlas_tex_) glGenTextures(1, &atlas_tex_);
  glActiveTexture(GL_TEXTURE0);
  glBindTexture(GL_TEXTURE_2D, atlas_tex_);
  glPixelStorei(GL_UNPACK_ALIGNMENT, 4);
  glTexImage2D(GL_TEXTURE_2D, 0, GL_RGBA8, std::max(1, atlas.width), std::max(1, atlas.height), 0, GL_RGBA,
               GL_UNSIGNED_BYTE, atlas.rgba.empty() ? nullptr : atlas.rgba.data());
  glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_MIN_FILTER, GL_LINEAR);
  glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_MAG_FILTER, GL_LINEAR);
  glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_WRAP_S, GL_CLAMP_TO_EDGE);
  glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_WRAP_T, GL_CLAMP_TO_EDGE);
  glBindTexture(GL_TEXTURE_2D, 0);
  const size_t nt = remote_triangles_.size();
  std::vector<BakedVertex> verts(nt * 3);
  for (size_t t = 0; t < nt; ++t) {
    for (int k = 0; k < 3; ++k) {
      BakedVertex& v = verts[3 * t + k];
      const Eigen::Vector3f& p = remote_positions_[remote_triangles_[t][k]];
      v.p[0] = p.x();
      v.p[1] = p.y();
      v.p[2] = p.z();
      v.uv[0] = atlas.uv[3 * t + k][0];
      v.uv[1] = atlas.uv[3 * t + k][1];
    }
  }
  if (!baked_.vao) {
    glGenVertexArrays(1, &baked_.vao);
    glGenBuffers(1, &baked_.vbo);
    glBindVertexArray(baked_.vao);
    glBindBuffer(GL_ARRAY_BUFFER, baked_.vbo);
    glEnableVertexAttribArray(0);
    glVertexAttribPointer(0, 3, GL_FLOAT, GL_FALSE, sizeof(BakedVertex), reinterpret_cast<void*>(offsetof(BakedVertex, p)));
    glEnableVertexAttribArray(1);
    glVertexAttribPointer(1, 2, GL_FLOAT, GL_FALSE, sizeof(BakedVertex),
                          reinterpret_cast<void*>(offsetof(BakedVertex, uv)));
  }
  glBindVertexArray(baked_.vao);
  glBindBuffer(GL_ARRAY_BUFFER, baked_.vbo);
  const size_t bytes = verts.size() * sizeof(BakedVertex);
  if (bytes > baked_.vbo_bytes) {
    glBufferData(GL_ARRAY_BUFFER, static_cast<GLsizeiptr>(bytes), verts.data(), GL_DYNAMIC_DRAW);
    baked_.vbo_bytes = bytes;
  } else if (bytes > 0) {
    glBufferSubData(GL_ARRAY_BUFFER, 0, static_cast<GLsizeiptr>(bytes), verts.data());
  }
  glBindVertexArray(0);
  baked_vertices_ = verts.size();
  atlas_stats_.width = atlas.width;
  atlas_stats_.height = atlas.height;
  atlas_stats_.texels = atlas.texels_baked;
  atlas_stats_.samples = atlas.samples;
  atlas_stats_.bake_ms = sw.ElapsedMs();
  return CheckGlError("atlas bake");
}

void Renderer::PodBox(const CameraModel& cam, int box[4]) const {
  const Intrinsics& in = cam.intrinsics;
  if (in.HasDistortion() || !(remote_min_.array() <= remote_max_.array()).all()) return;  // keep the whole image
  const Pose cam_from_world = cam.world_from_camera.inverse();
  float x0 = 1e30f, y0 = 1e30f, x1 = -1e30f, y1 = -1e30f;
  for (int c = 0; c < 8; ++c) {
    const Eigen::Vector3f corner((c & 1) ? remote_max_.x() : remote_min_.x(), (c & 2) ? remote_max_.y() : remote_min_.y(),
                                 (c & 4) ? remote_max_.z() : remote_min_.z());
    const Eigen::Vector3f p = cam_from_world * corner;
    if (p.z() < 0.05f) return;  // the box reaches behind the camera: whole image
    const float u = static_cast<float>(in.fx) * p.x() / p.z() + static_cast<float>(in.cx);
    const float v = static_cast<float>(in.fy) * p.y() / p.z() + static_cast<float>(in.cy);
    x0 = std::min(x0, u);
    x1 = std::max(x1, u);
    y0 = std::min(y0, v);
    y1 = std::max(y1, v);
  }
  constexpr float kMargin = 10.0f;  // > the largest discontinuity radius (8 px)
  const int bx0 = std::clamp(static_cast<int>(std::floor(x0 - kMargin)), 0, in.width);
  const int by0 = std::clamp(static_cast<int>(std::floor(y0 - kMargin)), 0, in.height);
  const int bx1 = std::clamp(static_cast<int>(std::ceil(x1 + kMargin)), 0, in.width);
  const int by1 = std::clamp(static_cast<int>(std::ceil(y1 + kMargin)), 0, in.height);
  // Texel row v is image row v: no flip between image and window rows here.
  box[0] = bx0;
  box[1] = by0;
  box[2] = std::max(0, bx1 - bx0);
  box[3] = std::max(0, by1 - by0);
}

Status Renderer::ReadPodDepth(int i, ImageFloat* out) {
  if (i < 0 || i >= num_pods_) return InvalidArgument("no pod " + std::to_string(i));
  if (visibility_dirty_) HOLO_RETURN_IF_ERROR(UpdateVisibility());
  if (!vis_gpu_) {
    const Intrinsics& in = pod_cameras_[i].intrinsics;
    out->Resize(in.width, in.height);
    std::copy(pod_raw_z_[i].begin(), pod_raw_z_[i].end(), out->data());
    return OkStatus();
  }
  GLint old_fbo = 0;
  glGetIntegerv(GL_READ_FRAMEBUFFER_BINDING, &old_fbo);
  glBindFramebuffer(GL_READ_FRAMEBUFFER, pod_fbo_);
  glFramebufferTextureLayer(GL_READ_FRAMEBUFFER, GL_COLOR_ATTACHMENT0, pod_raw_tex_, 0, i);
  const Intrinsics& in = pod_cameras_[i].intrinsics;
  out->Resize(in.width, in.height);
  glPixelStorei(GL_PACK_ALIGNMENT, 4);
  // Texel row v is image row v (the pass does not flip).
  glReadPixels(0, 0, in.width, in.height, GL_RED, GL_FLOAT, out->data());
  glBindFramebuffer(GL_READ_FRAMEBUFFER, static_cast<GLuint>(old_fbo));
  return CheckGlError("ReadPodDepth");
}

Status Renderer::Render(const CameraModel& camera, const RenderSettings& settings, const Viewport& vp) {
  if (vp.width <= 0 || vp.height <= 0) return InvalidArgument("empty viewport");
  HOLO_RETURN_IF_ERROR(camera.intrinsics.Check().WithContext("view camera"));
  if (!(settings.near_m > 0 && settings.far_m > settings.near_m)) {
    return InvalidArgument("need 0 < near_m < far_m");
  }
  const bool projective = settings.mode == ColorMode::kProjective;
  bool baked = false;
  if (projective && settings.projective.bake) {
    if (!AtlasCurrent(settings.projective)) HOLO_RETURN_IF_ERROR(UpdateAtlas(settings.projective));
    baked = !atlas_stats_.fallback;
  }
  if (projective && !baked) {
    HOLO_RETURN_IF_ERROR(PreparePods(settings.projective));
    HOLO_RETURN_IF_ERROR(SyncPodTexturesToGpu());
  }
  const Eigen::Matrix4f& local_from_remote = settings.local_from_remote;
  if (!local_from_remote.allFinite() || std::abs(local_from_remote.block<3, 3>(0, 0).determinant()) < 1e-12f) {
    return InvalidArgument("local_from_remote must be a finite, invertible transform");
  }
  glViewport(vp.x, vp.y, vp.width, vp.height);
  glEnable(GL_SCISSOR_TEST);
  glScissor(vp.x, vp.y, vp.width, vp.height);
  glClearColor(settings.background[0] / 255.0f, settings.background[1] / 255.0f, settings.background[2] / 255.0f,
               1.0f);
  glClearDepth(1.0);
  glDepthMask(GL_TRUE);
  glColorMask(GL_TRUE, GL_TRUE, GL_TRUE, GL_TRUE);
  glClear(GL_COLOR_BUFFER_BIT | GL_DEPTH_BUFFER_BIT);
  glEnable(GL_DEPTH_TEST);
  glDepthFunc(GL_LESS);
  glDisable(GL_CULL_FACE);
  glDisable(GL_BLEND);

  const Eigen::Matrix4f clip_from_local = ViewProjection(camera, settings.near_m, settings.far_m);
  HOLO_ASSIGN_OR_RETURN(const unsigned plain, DrawProgram(0));
  glUseProgram(plain);
  SetMat4(plain, "u_clip_from_local", clip_from_local);

  // Local geometry first: it fills the depth buffer, so remote fragments
  // behind it are discarded by the depth test.
  if (settings.composite_local && local_.index_count > 0) {
    SetMat4(plain, "u_local_from_remote", Eigen::Matrix4f::Identity());
    if (!settings.show_local) glColorMask(GL_FALSE, GL_FALSE, GL_FALSE, GL_FALSE);
    Draw(local_);
    glColorMask(GL_TRUE, GL_TRUE, GL_TRUE, GL_TRUE);
  }

  SetMat4(plain, "u_local_from_remote", local_from_remote);
  if (settings.cull_back_faces) {
    // Counter-clockwise seen from outside stays counter-clockwise in window
    // coordinates (the y flip of the projection undoes the camera's y-down).
    glFrontFace(GL_CCW);
    glCullFace(GL_BACK);
    glEnable(GL_CULL_FACE);
  }
  if (!projective) {
    Draw(remote_);
  } else if (baked) {
    glUseProgram(baked_program_);
    SetMat4(baked_program_, "u_clip_from_local", clip_from_local);
    SetMat4(baked_program_, "u_local_from_remote", local_from_remote);
    glActiveTexture(GL_TEXTURE0);
    glBindTexture(GL_TEXTURE_2D, atlas_tex_);
    if (baked_vertices_ > 0) {
      glBindVertexArray(baked_.vao);
      glDrawArrays(GL_TRIANGLES, 0, static_cast<GLsizei>(baked_vertices_));
      glBindVertexArray(0);
    }
    glBindTexture(GL_TEXTURE_2D, 0);
  } else {
    if (settings.depth_prepass) {
      // Depth first with the cheap colour program, then the projective
      // shaders only on the visible surface (GL_LEQUAL on identical
      // positions: gl_Position is invariant): each pixel is textured once.
      glColorMask(GL_FALSE, GL_FALSE, GL_FALSE, GL_FALSE);
      Draw(remote_);
      glColorMask(GL_TRUE, GL_TRUE, GL_TRUE, GL_TRUE);
      glDepthFunc(GL_LEQUAL);
      glDepthMask(GL_FALSE);
    }
    const int n = num_pods_;
    std::vector<float> cam_from_world(16 * n), intr(4 * n), dist(4 * n), k3(n), size(2 * n), center(3 * n);
    bool distorted = false;
    for (int i = 0; i < n; ++i) distorted |= pod_cameras_[i].intrinsics.HasDistortion();
    for (int i = 0; i < n; ++i) {
      const CameraModel& c = pod_cameras_[i];
      Eigen::Matrix4f m = c.world_from_camera.inverse().matrix();
      if (!distorted) {
        Eigen::Matrix4f k = Eigen::Matrix4f::Identity();
        k(0, 0) = static_cast<float>(c.intrinsics.fx);
        k(1, 1) = static_cast<float>(c.intrinsics.fy);
        k(0, 2) = static_cast<float>(c.intrinsics.cx);
        k(1, 2) = static_cast<float>(c.intrinsics.cy);
        m = k * m;
      }
      std::copy(m.data(), m.data() + 16, cam_from_world.data() + 16 * i);
      const Intrinsics& in = c.intrinsics;
      intr[4 * i + 0] = static_cast<float>(in.fx);
      intr[4 * i + 1] = static_cast<float>(in.fy);
      intr[4 * i + 2] = static_cast<float>(in.cx);
      intr[4 * i + 3] = static_cast<float>(in.cy);
      for (int k = 0; k < 4; ++k) dist[4 * i + k] = static_cast<float>(in.distortion[k]);
      k3[i] = static_cast<float>(in.distortion[4]);
      size[2 * i + 0] = static_cast<float>(in.width);
      size[2 * i + 1] = static_cast<float>(in.height);
      const Eigen::Vector3f ctr = c.Center();
      for (int k = 0; k < 3; ++k) center[3 * i + k] = ctr[k];
    }
    const Eigen::Vector4f eye_local(camera.Center().x(), camera.Center().y(), camera.Center().z(), 1.0f);
    const Eigen::Vector4f eye_remote = local_from_remote.inverse() * eye_local;
    const ProjectiveOptions& po = settings.projective;
    glActiveTexture(GL_TEXTURE0);
    glBindTexture(GL_TEXTURE_2D_ARRAY, pod_color_tex_);
    glActiveTexture(GL_TEXTURE1);
    glBindTexture(GL_TEXTURE_2D_ARRAY, pod_depth_tex_);
    // One draw call per pod set; the slot uniforms are that set's pods.
    std::array<bool, kMaxPods + 1> frame_uniforms_set{};
    std::vector<float> s_cam(16 * kMaxPods), s_intr(4 * kMaxPods), s_dist(4 * kMaxPods), s_k3(kMaxPods),
        s_size(2 * kMaxPods), s_center(3 * kMaxPods);
    std::vector<int> s_pod(kMaxPods);
    glBindVertexArray(remote_.vao);
    for (const PodSet& set : pod_sets_) {
      const int slots = set.num_pods;
      HOLO_ASSIGN_OR_RETURN(const unsigned prog, DrawProgram(slots));
      glUseProgram(prog);
      if (!frame_uniforms_set[slots]) {
        frame_uniforms_set[slots] = true;
        SetMat4(prog, "u_clip_from_local", clip_from_local);
        SetMat4(prog, "u_local_from_remote", local_from_remote);
        if (slots > 0) {
          glUniform1i(Loc(prog, "u_distorted"), distorted ? 1 : 0);
          glUniform2f(Loc(prog, "u_array_size"), static_cast<float>(array_width_), static_cast<float>(array_height_));
          glUniform3f(Loc(prog, "u_eye_remote"), eye_remote.x() / eye_remote.w(), eye_remote.y() / eye_remote.w(),
                      eye_remote.z() / eye_remote.w());
          glUniform1f(Loc(prog, "u_alpha"), po.alpha);
          glUniform1f(Loc(prog, "u_beta"), po.beta);
          glUniform1f(Loc(prog, "u_vis_tol"), po.visibility_tolerance_m);
          glUniform1f(Loc(prog, "u_edge_weight"), po.discontinuity_weight);
          glUniform1f(Loc(prog, "u_min_confidence"),
                      po.use_masks && !pod_masks_.empty() && remote_has_colors_ ? po.min_mask_confidence : 0.0f);
        }
      }
      if (slots > 0) {
        for (int k = 0; k < slots; ++k) {
          const int i = set.pods[k];
          std::copy_n(&cam_from_world[16 * i], 16, &s_cam[16 * k]);
          std::copy_n(&intr[4 * i], 4, &s_intr[4 * k]);
          std::copy_n(&dist[4 * i], 4, &s_dist[4 * k]);
          s_k3[k] = k3[i];
          std::copy_n(&size[2 * i], 2, &s_size[2 * k]);
          std::copy_n(&center[3 * i], 3, &s_center[3 * k]);
          s_pod[k] = i;
        }
        glUniformMatrix4fv(Loc(prog, "u_slot_cam_from_world"), slots, GL_FALSE, s_cam.data());
        glUniform4fv(Loc(prog, "u_slot_intr"), slots, s_intr.data());
        glUniform4fv(Loc(prog, "u_slot_dist"), slots, s_dist.data());
        glUniform1fv(Loc(prog, "u_slot_k3"), slots, s_k3.data());
        glUniform2fv(Loc(prog, "u_slot_size"), slots, s_size.data());
        glUniform3fv(Loc(prog, "u_slot_center"), slots, s_center.data());
        glUniform1iv(Loc(prog, "u_slot_pod"), slots, s_pod.data());
      }
      glDrawElements(GL_TRIANGLES, static_cast<GLsizei>(set.index_count), GL_UNSIGNED_INT,
                     reinterpret_cast<void*>(set.first_index * sizeof(uint32_t)));
    }
    glBindVertexArray(0);
  }
  glDisable(GL_CULL_FACE);
  glDepthMask(GL_TRUE);
  glDepthFunc(GL_LESS);
  glActiveTexture(GL_TEXTURE1);
  glBindTexture(GL_TEXTURE_2D_ARRAY, 0);
  glActiveTexture(GL_TEXTURE0);
  glBindTexture(GL_TEXTURE_2D_ARRAY, 0);
  glUseProgram(0);
  glDisable(GL_SCISSOR_TEST);
  return CheckGlError("Renderer::Render");
}

}  // namespace holo::render
