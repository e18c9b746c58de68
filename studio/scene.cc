#include "studio/scene.h"

#include <algorithm>
#include <cmath>
#include <limits>

#include "common/mesh.h"
#include "common/status.h"

namespace holo::studio {
namespace {

using Eigen::AngleAxisf;
using Eigen::Isometry3f;
using Eigen::Translation3f;
using Eigen::Vector3f;

constexpr float kPi = 3.14159265358979f;
constexpr float kDeg = kPi / 180.0f;
constexpr int kFigureParts = 16;

enum FigurePart {
  kPelvis = 0, kTorso, kNeck, kHeadPart,
  kUpperArmL, kUpperArmR, kLowerArmL, kLowerArmR, kHandL, kHandR,
  kUpperLegL, kUpperLegR, kLowerLegL, kLowerLegR, kFootL, kFootR,
};

Isometry3f T(float x, float y, float z) { return Isometry3f(Translation3f(x, y, z)); }
Isometry3f Rx(float a) { return Isometry3f(AngleAxisf(a, Vector3f::UnitX())); }
Isometry3f Ry(float a) { return Isometry3f(AngleAxisf(a, Vector3f::UnitY())); }
Isometry3f Rz(float a) { return Isometry3f(AngleAxisf(a, Vector3f::UnitZ())); }

float Smoothstep(float a, float b, float x) {
  const float t = std::clamp((x - a) / (b - a), 0.0f, 1.0f);
  return t * t * (3.0f - 2.0f * t);
}

// Joint angles of one figure, radians.
struct FigureAngles {
  float torso_twist = 0, torso_lean = 0, head_yaw = 0, head_pitch = 0;
  float sh_abd[2] = {0, 0}, sh_flex[2] = {0, 0}, el_bend[2] = {0, 0}, el_flex[2] = {0, 0};
  float hip_flex[2] = {0, 0}, knee[2] = {0, 0}, ankle[2] = {0, 0};
};

// Part poses in the figure frame (x forward, y left, z up, feet at z = 0).
void FigureFk(const FigureAngles& a, Isometry3f* p) {
  p[kPelvis] = T(0, 0, 0.95f);
  p[kTorso] = p[kPelvis] * T(0, 0, 0.05f) * Rz(a.torso_twist) * Ry(a.torso_lean);
  p[kNeck] = p[kTorso] * T(0, 0, 0.42f);
  p[kHeadPart] = p[kNeck] * T(0, 0, 0.09f) * Rz(a.head_yaw) * Ry(a.head_pitch);
  for (int s = 0; s < 2; ++s) {
    const float sy = s == 0 ? 1.0f : -1.0f;
    p[kUpperArmL + s] = p[kTorso] * T(0, sy * 0.205f, 0.355f) * Rx(sy * a.sh_abd[s]) * Ry(-a.sh_flex[s]);
    p[kLowerArmL + s] = p[kUpperArmL + s] * T(0, 0, -0.28f) * Rx(sy * a.el_bend[s]) * Ry(-a.el_flex[s]);
    p[kHandL + s] = p[kLowerArmL + s] * T(0, 0, -0.25f);
    p[kUpperLegL + s] = p[kPelvis] * T(0, sy * 0.09f, -0.05f) * Ry(-a.hip_flex[s]);
    p[kLowerLegL + s] = p[kUpperLegL + s] * T(0, 0, -0.43f) * Ry(a.knee[s]);
    p[kFootL + s] = p[kLowerLegL + s] * T(0, 0, -0.415f) * Ry(a.ankle[s]);
  }
}

struct FigurePlacement {
  float x, y, yaw0, phase;
};

FigurePlacement Placement(int figure, int num_figures) {
  if (num_figures == 1) return {0.0f, 0.0f, 0.0f, 0.0f};
  if (figure == 0) return {0.05f, 0.55f, -20.0f * kDeg, 0.0f};
  return {-0.05f, -0.55f, 200.0f * kDeg, 2.1f};
}

// One step cycle of walking in place (both feet), seconds; a foot lands every half cycle.
constexpr float kStepPeriodS = 1.3f;
// The ball touches the floor every this many seconds.
constexpr float kBounceIntervalS = 1.05f;

// Walk in place, turn slowly, wave with the right arm now and then.
FigureAngles Animate(double t_seconds, float phase, float* root_yaw) {
  const float t = static_cast<float>(t_seconds);
  FigureAngles a;
  const float ph = 2.0f * kPi * t / kStepPeriodS + phase;
  auto lift = [](float x) {
    const float s = std::max(0.0f, std::sin(x));
    return 30.0f * kDeg * s * s;
  };
  a.hip_flex[0] = lift(ph);
  a.hip_flex[1] = lift(ph + kPi);
  for (int s = 0; s < 2; ++s) {
    a.knee[s] = 1.7f * a.hip_flex[s];
    a.ankle[s] = a.hip_flex[s] - a.knee[s];  // keeps the foot level
  }
  const float w = Smoothstep(0.25f, 0.75f, 0.5f + 0.5f * std::sin(2.0f * kPi * t / 7.0f + 1.3f * phase - 1.0f));
  a.sh_abd[0] = 10.0f * kDeg;
  a.sh_flex[0] = -14.0f * kDeg * std::sin(ph);
  a.el_flex[0] = 12.0f * kDeg;
  a.sh_abd[1] = (12.0f + 78.0f * w) * kDeg;
  a.sh_flex[1] = (1.0f - w) * 14.0f * kDeg * std::sin(ph);
  a.el_flex[1] = (1.0f - w) * 12.0f * kDeg;
  a.el_bend[1] = w * (95.0f + 22.0f * std::sin(2.0f * kPi * 1.7f * t)) * kDeg;
  a.torso_twist = 6.0f * kDeg * std::sin(ph);
  a.torso_lean = 3.0f * kDeg;
  a.head_yaw = 20.0f * kDeg * std::sin(2.0f * kPi * t / 4.5f + phase);
  a.head_pitch = 5.0f * kDeg * std::sin(2.0f * kPi * t / 3.1f);
  *root_yaw = 55.0f * kDeg * std::sin(2.0f * kPi * t / 10.0f + phase);
  return a;
}

// Builds one rigid part's geometry.
class PartBuilder {
 public:
  PartBuilder(SceneTemplate* t, int part, uint8_t material, uint8_t palette, const Isometry3f& rest_pose,
              bool tex_in_rest)
      : t_(t), part_(part), material_(material), palette_(palette), rest_(rest_pose), tex_in_rest_(tex_in_rest) {}

  // Capsule along local z from (cx, cy, z0) to (cx, cy, z1) with an
  // elliptic section (rx, ry) and caps of axial radius rcap. z0 == z1 gives
  // an ellipsoid with radii (rx, ry, rcap).
  void Capsule(float cx, float cy, float z0, float z1, float rx, float ry, float rcap, int nseg, int ncap, int nbody) {
    Mesh m;
    std::vector<std::pair<float, float>> rings;  // (axial position, section scale)
    for (int i = 1; i <= ncap; ++i) {
      const float phi = -0.5f * kPi + i * (0.5f * kPi) / ncap;
      rings.push_back({z0 + rcap * std::sin(phi), std::cos(phi)});
    }
    if (z1 > z0)
      for (int k = 1; k <= nbody; ++k) rings.push_back({z0 + (z1 - z0) * k / nbody, 1.0f});
    for (int i = 1; i < ncap; ++i) {
      const float phi = i * (0.5f * kPi) / ncap;
      rings.push_back({z1 + rcap * std::sin(phi), std::cos(phi)});
    }
    m.positions.push_back({cx, cy, z0 - rcap});
    for (const auto& [s, k] : rings)
      for (int j = 0; j < nseg; ++j) {
        const float th = 2.0f * kPi * j / nseg;
        m.positions.push_back({cx + k * rx * std::cos(th), cy + k * ry * std::sin(th), s});
      }
    m.positions.push_back({cx, cy, z1 + rcap});
    const uint32_t nr = static_cast<uint32_t>(rings.size());
    const uint32_t top = 1 + nr * nseg;
    auto v = [&](uint32_t r, int j) { return 1 + r * nseg + static_cast<uint32_t>(j % nseg); };
    for (int j = 0; j < nseg; ++j) {
      m.triangles.push_back({0, v(0, j + 1), v(0, j)});
      for (uint32_t r = 0; r + 1 < nr; ++r) {
        m.triangles.push_back({v(r, j), v(r, j + 1), v(r + 1, j + 1)});
        m.triangles.push_back({v(r, j), v(r + 1, j + 1), v(r + 1, j)});
      }
      m.triangles.push_back({top, v(nr - 1, j), v(nr - 1, j + 1)});
    }
    m.ComputeNormals();
    Add(m);
  }

  // Axis-aligned box centred at the origin, `n`×`n` quads per face.
  void Box(float half, int n) {
    Mesh m;
    for (int axis = 0; axis < 3; ++axis)
      for (int sign = -1; sign <= 1; sign += 2) {
        Vector3f nrm = Vector3f::Zero();
        nrm[axis] = static_cast<float>(sign);
        Vector3f u = Vector3f::Zero(), w = Vector3f::Zero();
        u[(axis + 1) % 3] = 1.0f;
        w[(axis + 2) % 3] = 1.0f;
        if (sign < 0) std::swap(u, w);  // keep counter-clockwise seen from outside
        const uint32_t base = static_cast<uint32_t>(m.positions.size());
        for (int i = 0; i <= n; ++i)
          for (int j = 0; j <= n; ++j) {
            const float a = -half + 2.0f * half * i / n, b = -half + 2.0f * half * j / n;
            m.positions.push_back(nrm * half + u * a + w * b);
            m.normals.push_back(nrm);
          }
        auto id = [&](int i, int j) { return base + static_cast<uint32_t>(i * (n + 1) + j); };
        for (int i = 0; i < n; ++i)
          for (int j = 0; j < n; ++j) {
            m.triangles.push_back({id(i, j), id(i + 1, j), id(i + 1, j + 1)});
            m.triangles.push_back({id(i, j), id(i + 1, j + 1), id(i, j + 1)});
          }
      }
    Add(m);
  }

 private:
  void Add(const Mesh& m) {
    const uint32_t base = static_cast<uint32_t>(t_->local_pos.size());
    for (size_t i = 0; i < m.positions.size(); ++i) {
      const Vector3f tex = tex_in_rest_ ? Vector3f(rest_ * m.positions[i]) : m.positions[i];
      t_->local_pos.push_back(m.positions[i]);
      t_->local_normal.push_back(m.normals[i]);
      t_->tex.push_back(tex);
      t_->vertex_part.push_back(static_cast<uint16_t>(part_));
      const Vector3f c = Albedo(material_, palette_, tex) * 255.0f;
      t_->vertex_albedo.push_back({static_cast<uint8_t>(std::lround(std::clamp(c.x(), 0.0f, 255.0f))),
                                   static_cast<uint8_t>(std::lround(std::clamp(c.y(), 0.0f, 255.0f))),
                                   static_cast<uint8_t>(std::lround(std::clamp(c.z(), 0.0f, 255.0f)))});
    }
    for (const auto& tri : m.triangles) {
      t_->triangles.push_back({tri[0] + base, tri[1] + base, tri[2] + base});
      t_->tri_material.push_back(material_);
      t_->tri_palette.push_back(palette_);
    }
  }

  SceneTemplate* t_;
  int part_;
  uint8_t material_, palette_;
  Isometry3f rest_;
  bool tex_in_rest_;
};

void BuildFigure(SceneTemplate* t, int first_part, uint8_t palette) {
  Isometry3f rest[kFigureParts];
  FigureFk(FigureAngles{}, rest);
  auto part = [&](int p, uint8_t material) {
    const bool in_rest = material != kHead;
    return PartBuilder(t, first_part + p, material, palette, rest[p], in_rest);
  };
  part(kPelvis, kTrousers).Capsule(0, 0, -0.02f, -0.02f, 0.11f, 0.165f, 0.11f, 32, 8, 0);
  part(kTorso, kShirt).Capsule(0, 0, 0.08f, 0.33f, 0.105f, 0.165f, 0.1f, 40, 8, 12);
  part(kNeck, kSkin).Capsule(0, 0, 0.0f, 0.07f, 0.05f, 0.05f, 0.04f, 20, 4, 3);
  part(kHeadPart, kHead).Capsule(0.01f, 0, 0.11f, 0.11f, 0.10f, 0.085f, 0.12f, 40, 14, 0);
  for (int s = 0; s < 2; ++s) {
    part(kUpperArmL + s, kShirt).Capsule(0, 0, -0.27f, 0.0f, 0.048f, 0.048f, 0.048f, 24, 5, 8);
    part(kLowerArmL + s, kSkin).Capsule(0, 0, -0.24f, 0.0f, 0.04f, 0.038f, 0.04f, 20, 5, 8);
    part(kHandL + s, kSkin).Capsule(0, 0, -0.08f, -0.08f, 0.042f, 0.022f, 0.085f, 20, 7, 0);
    part(kUpperLegL + s, kTrousers).Capsule(0, 0, -0.42f, 0.0f, 0.075f, 0.07f, 0.07f, 28, 5, 12);
    part(kLowerLegL + s, kTrousers).Capsule(0, 0, -0.40f, 0.0f, 0.055f, 0.055f, 0.05f, 24, 5, 12);
    part(kFootL + s, kShoes).Capsule(0.05f, 0, -0.01f, -0.01f, 0.13f, 0.05f, 0.042f, 24, 7, 0);
  }
}

}  // namespace

Scene::Scene(const SceneConfig& config) : config_(config) {
  if (config_.empty_room) return;
  int part = 0;
  for (int f = 0; f < config_.num_figures; ++f) {
    BuildFigure(&tmpl_, part, static_cast<uint8_t>(f));
    for (int p = 0; p < kFigureParts; ++p) part_owner_.push_back(f);
    part += kFigureParts;
  }
  for (int k = 0; k < config_.num_props; ++k) {
    const uint8_t palette = static_cast<uint8_t>(k);
    if (k % 2 == 0) {
      PartBuilder(&tmpl_, part, kBall, palette, Isometry3f::Identity(), false)
          .Capsule(0, 0, 0, 0, 0.11f, 0.11f, 0.11f, 32, 12, 0);
    } else {
      PartBuilder(&tmpl_, part, kBox, palette, Isometry3f::Identity(), false).Box(0.12f, 4);
    }
    part_owner_.push_back(config_.num_figures + k);
    ++part;
  }
  tmpl_.num_parts = part;
}

void Scene::PartPoses(double t, std::vector<Isometry3f>* poses) const {
  poses->resize(tmpl_.num_parts);
  int part = 0;
  for (int f = 0; f < config_.num_figures && tmpl_.num_parts > 0; ++f) {
    const FigurePlacement pl = Placement(f, config_.num_figures);
    float yaw = 0;
    const FigureAngles a = Animate(t, pl.phase, &yaw);
    Isometry3f local[kFigureParts];
    FigureFk(a, local);
    const Isometry3f root = T(pl.x, pl.y, 0.0f) * Rz(pl.yaw0 + yaw);
    for (int p = 0; p < kFigureParts; ++p) (*poses)[part + p] = root * local[p];
    part += kFigureParts;
  }
  const float orbit = config_.num_figures == 1 ? 0.85f : 1.15f;
  const float tf = static_cast<float>(t);
  for (int k = 0; k < config_.num_props && part < tmpl_.num_parts; ++k, ++part) {
    if (k % 2 == 0) {
      // A ball bouncing around the figures, spinning.
      const float phi = 0.6f + 0.9f * k + 2.0f * kPi * tf / 9.0f;
      const float z = 0.11f + 0.7f * std::abs(std::sin(kPi * tf / kBounceIntervalS));
      (*poses)[part] = T(orbit * std::cos(phi), orbit * std::sin(phi), z) *
                       Isometry3f(AngleAxisf(2.3f * tf, Vector3f(0.3f, 1.0f, 0.2f).normalized()));
    } else {
      // A crate hopping the other way round, turning.
      const float phi = 0.6f + kPi - 2.0f * kPi * tf / 11.0f;
      const float z = 0.1201f + 0.35f * std::abs(std::sin(kPi * tf / 0.8f));
      (*poses)[part] = T(orbit * std::cos(phi), orbit * std::sin(phi), z) * Rz(1.3f * tf);
    }
  }
}

void Scene::SoundEvents(double t0, double t1, std::vector<std::pair<double, int>>* events) const {
  events->clear();
  if (config_.empty_room || !(t1 > t0)) return;
  // A foot lands when the step phase 2π t / kStepPeriodS + phase passes a
  // multiple of π (lift() in Animate is zero from there on).
  if (config_.num_figures > 0) {
    const double half = kStepPeriodS / 2.0;
    const double shift = -static_cast<double>(Placement(0, config_.num_figures).phase) * kStepPeriodS / (2.0 * kPi);
    for (double k = std::ceil((t0 - shift) / half); shift + k * half < t1; k += 1.0) {
      events->push_back({shift + k * half, 0});
    }
  }
  // The ball (prop 0) touches the floor where |sin(π t / kBounceIntervalS)| = 0.
  if (config_.num_props > 0) {
    for (double k = std::ceil(t0 / kBounceIntervalS); k * kBounceIntervalS < t1; k += 1.0) {
      events->push_back({k * kBounceIntervalS, 1});
    }
  }
  std::sort(events->begin(), events->end());
}

Isometry3f Scene::HeadPose(double t, int figure) const {
  if (figure < 0 || figure >= config_.num_figures || config_.empty_room) return Isometry3f::Identity();
  std::vector<Isometry3f> poses;
  PartPoses(t, &poses);
  // The head ellipsoid is centred 0.11 m above the head joint, 1 cm forward.
  return poses[static_cast<size_t>(figure * kFigureParts + kHeadPart)] * T(0.01f, 0.0f, 0.11f);
}

void Scene::Pose(double t, std::vector<Vector3f>* positions, std::vector<Vector3f>* normals,
                 std::vector<Isometry3f>* scratch_poses) const {
  PartPoses(t, scratch_poses);
  const size_t n = tmpl_.local_pos.size();
  positions->resize(n);
  normals->resize(n);
  for (size_t i = 0; i < n; ++i) {
    const Isometry3f& p = (*scratch_poses)[tmpl_.vertex_part[i]];
    (*positions)[i] = p * tmpl_.local_pos[i];
    (*normals)[i] = p.linear() * tmpl_.local_normal[i];
  }
}

namespace {

Vector3f Rgb(int r, int g, int b) { return Vector3f(r, g, b) / 255.0f; }

uint32_t Hash2(int a, int b) {
  uint32_t h = static_cast<uint32_t>(a) * 0x8da6b343u ^ static_cast<uint32_t>(b) * 0xd8163841u;
  h ^= h >> 15;
  h *= 0x2c1b3c6du;
  h ^= h >> 12;
  return h;
}
float Hash01(int a, int b) { return (Hash2(a, b) & 0xffff) / 65535.0f; }

bool InEllipse(float x, float y, float cx, float cy, float rx, float ry) {
  const float dx = (x - cx) / rx, dy = (y - cy) / ry;
  return dx * dx + dy * dy < 1.0f;
}

Vector3f HeadAlbedo(uint8_t palette, const Vector3f& tex) {
  const Vector3f skin = palette == 0 ? Rgb(234, 190, 160) : Rgb(150, 105, 75);
  const Vector3f hair = palette == 0 ? Rgb(95, 55, 25) : Rgb(25, 20, 18);
  // Normalised head coordinates: x forward (face), y left, z up, each in [-1, 1].
  const float qx = (tex.x() - 0.01f) / 0.10f, qy = tex.y() / 0.085f, qz = (tex.z() - 0.11f) / 0.12f;
  if (qz > 0.42f - 0.25f * std::max(0.0f, -qx) || (qx < -0.25f && qz > -0.55f)) return hair;
  if (qx > 0.3f) {
    for (int s = -1; s <= 1; s += 2) {
      const float ey = 0.36f * s;
      if (InEllipse(qy, qz, ey, 0.36f, 0.2f, 0.04f)) return hair;  // eyebrow
      if (InEllipse(qy, qz, ey, 0.16f, 0.17f, 0.10f)) {
        if (InEllipse(qy, qz, ey, 0.16f, 0.07f, 0.07f)) return palette == 0 ? Rgb(40, 80, 150) : Rgb(60, 40, 20);
        return Rgb(245, 245, 240);
      }
    }
    if (InEllipse(qy, qz, 0.0f, -0.43f, 0.3f, 0.07f)) return Rgb(180, 40, 50);  // mouth
    if (std::abs(qy) < 0.08f && qz > -0.25f && qz < 0.1f) return skin * 0.82f;  // nose
    if (InEllipse(qy, qz, 0.0f, -0.15f, 0.55f, 0.2f)) return skin * 1.03f;
  }
  if (std::abs(qy) > 0.93f && std::abs(qz + 0.05f) < 0.18f && qx > -0.3f && qx < 0.2f) return skin * 0.85f;  // ears
  return skin;
}

}  // namespace

Vector3f Albedo(uint8_t material, uint8_t palette, const Vector3f& tex) {
  switch (material) {
    case kSkin:
      return palette == 0 ? Rgb(234, 190, 160) : Rgb(150, 105, 75);
    case kHead:
      return HeadAlbedo(palette, tex);
    case kShirt: {
      const bool stripe = std::fmod(tex.z() + 10.0f, 0.07f) < 0.035f;
      if (palette == 0) return stripe ? Rgb(200, 30, 40) : Rgb(240, 240, 235);
      return stripe ? Rgb(30, 140, 70) : Rgb(245, 215, 60);
    }
    case kTrousers: {
      const float c = 0.06f;
      const int k = static_cast<int>(std::floor(tex.x() / c) + std::floor(tex.y() / c) + std::floor(tex.z() / c));
      if (palette == 0) return (k & 1) ? Rgb(40, 60, 140) : Rgb(110, 150, 210);
      return (k & 1) ? Rgb(70, 70, 75) : Rgb(170, 160, 140);
    }
    case kShoes:
      return tex.z() < 0.018f ? Rgb(235, 235, 235) : Rgb(60, 35, 25);
    case kBall: {
      const Vector3f d = tex.normalized();
      if (std::abs(d.z()) > 0.9f) return Rgb(250, 250, 250);
      const float lon = std::atan2(d.y(), d.x());
      const int seg = static_cast<int>(std::floor((lon + kPi) / (2.0f * kPi) * 6.0f)) % 6;
      static const Vector3f kColors[6] = {Rgb(230, 40, 40), Rgb(250, 250, 250), Rgb(40, 90, 220),
                                          Rgb(250, 210, 30), Rgb(40, 170, 60), Rgb(250, 250, 250)};
      return kColors[(seg + palette) % 6];
    }
    case kBox: {
      const Vector3f a = tex.cwiseAbs();
      int axis = 0;
      if (a.y() > a[axis]) axis = 1;
      if (a.z() > a[axis]) axis = 2;
      const float u = tex[(axis + 1) % 3], v = tex[(axis + 2) % 3];
      if (std::max(std::abs(u), std::abs(v)) > 0.105f) return Rgb(90, 60, 30);  // frame
      const int k = static_cast<int>(std::floor(u / 0.05f) + std::floor(v / 0.05f));
      const Vector3f c = palette % 2 == 0 ? Rgb(240, 130, 20) : Rgb(150, 60, 190);
      return (k & 1) ? c : Rgb(245, 240, 225);
    }
    default:
      return Rgb(255, 0, 255);
  }
}

namespace {

Vector3f FloorAlbedo(float x, float y) {
  // Wooden planks along x, 0.18 m wide, 1.2 m long, staggered, dark seams.
  const float w = 0.18f, len = 1.2f;
  const int row = static_cast<int>(std::floor(y / w));
  const float xs = x + 0.37f * len * static_cast<float>(row % 3 + 3);
  const int col = static_cast<int>(std::floor(xs / len));
  const float fy = y / w - std::floor(y / w), fx = xs / len - std::floor(xs / len);
  if (fy < 0.03f || fx < 0.006f) return Rgb(60, 40, 25);
  const float shade = 0.8f + 0.35f * Hash01(row, col);
  const float grain = 0.93f + 0.07f * std::sin(xs * 37.0f + 9.0f * fy + 5.0f * Hash01(col, row));
  return Rgb(170, 120, 75) * (shade * grain);
}

Vector3f WallAlbedo(int wall, float u, float z) {
  static const Vector3f kBase[4] = {Rgb(200, 210, 185), Rgb(215, 195, 170), Rgb(185, 200, 220), Rgb(220, 205, 210)};
  if (z < 0.12f) return Rgb(80, 70, 65);  // skirting board
  // A poster on each wall, a different pattern each.
  const float pu = -0.4f + 0.6f * wall, pz = 1.2f;
  if (std::abs(u - pu) < 0.45f && std::abs(z - pz - 0.3f) < 0.35f) {
    const float lu = u - pu, lz = z - pz - 0.3f;
    if (std::abs(lu) > 0.42f || std::abs(lz) > 0.32f) return Rgb(30, 30, 30);
    switch (wall) {
      case 0: return ((static_cast<int>(std::floor(lu / 0.1f)) + static_cast<int>(std::floor(lz / 0.1f))) & 1)
                         ? Rgb(30, 30, 120) : Rgb(240, 200, 40);
      case 1: return (std::hypot(lu, lz) < 0.2f) ? Rgb(200, 40, 40) : Rgb(240, 240, 240);
      case 2: return std::fmod(lu + lz + 5.0f, 0.12f) < 0.06f ? Rgb(20, 130, 120) : Rgb(240, 150, 120);
      default: return Rgb(60 + static_cast<int>(150 * Hash01(static_cast<int>(std::floor(lu / 0.14f)), 7)),
                          120, 60 + static_cast<int>(150 * Hash01(static_cast<int>(std::floor(lz / 0.16f)), 3)));
    }
  }
  // Wallpaper: soft vertical stripes with a small diamond motif.
  const bool stripe = std::fmod(u + 10.0f, 0.3f) < 0.15f;
  Vector3f c = kBase[wall] * (stripe ? 1.0f : 0.9f);
  const float mu = std::fmod(u + 10.075f, 0.3f) - 0.15f, mz = std::fmod(z, 0.3f) - 0.15f;
  if (stripe && std::abs(mu) + std::abs(mz) < 0.03f) c *= 0.75f;
  return c;
}

}  // namespace

bool IntersectRoom(const Vector3f& o, const Vector3f& d, RoomHit* hit) {
  const float lo[3] = {-kRoomHalf, -kRoomHalf, 0.0f};
  const float hi[3] = {kRoomHalf, kRoomHalf, kRoomHeight};
  float best = std::numeric_limits<float>::infinity();
  int axis = -1;
  for (int a = 0; a < 3; ++a) {
    if (o[a] < lo[a] || o[a] > hi[a]) return false;
    if (d[a] == 0.0f) continue;
    const float t = ((d[a] > 0 ? hi[a] : lo[a]) - o[a]) / d[a];
    if (t < best) {
      best = t;
      axis = a;
    }
  }
  if (axis < 0) return false;
  hit->t = best;
  hit->normal = Vector3f::Zero();
  hit->normal[axis] = d[axis] > 0 ? -1.0f : 1.0f;
  const Vector3f p = o + best * d;
  if (axis == 2) {
    hit->albedo = d.z() < 0 ? FloorAlbedo(p.x(), p.y()) : Rgb(225, 225, 220);
  } else {
    // Walls numbered +x, +y, -x, -y; u runs along the wall.
    const int wall = axis == 0 ? (d.x() > 0 ? 0 : 2) : (d.y() > 0 ? 1 : 3);
    const float u = axis == 0 ? p.y() : p.x();
    hit->albedo = WallAlbedo(wall, u, p.z());
  }
  return true;
}

Vector3f LightDirection() {
  const float az = 35.0f * kDeg, el = 55.0f * kDeg;
  return Vector3f(std::cos(el) * std::cos(az), std::cos(el) * std::sin(az), std::sin(el));
}

}  // namespace holo::studio
