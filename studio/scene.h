// Internal to the synthetic studio: the procedural scene (articulated figures,
// props, room, light), its animation and its materials. Not a public API.
#pragma once

#include <array>
#include <cstdint>
#include <utility>
#include <vector>

#include <Eigen/Core>
#include <Eigen/Geometry>

namespace holo::studio {

enum Material : uint8_t {
  kSkin = 0,
  kHead,      // skin with a face and hair, textured in head coordinates
  kShirt,     // striped, textured in rest-pose figure coordinates
  kTrousers,  // checkered, rest-pose figure coordinates
  kShoes,
  kBall,      // beach ball, ball coordinates
  kBox,       // checkered crate, box coordinates
};

// The foreground objects (figures, then props) as one template mesh. Every
// vertex belongs to one rigid part; posing a frame only moves parts.
struct SceneTemplate {
  std::vector<Eigen::Vector3f> local_pos;     // in the part's frame
  std::vector<Eigen::Vector3f> local_normal;  // in the part's frame
  std::vector<Eigen::Vector3f> tex;           // texture coordinates (material dependent), metres
  std::vector<uint16_t> vertex_part;
  std::vector<std::array<uint32_t, 3>> triangles;
  std::vector<uint8_t> tri_material;
  std::vector<uint8_t> tri_palette;          // which figure/prop: colour palette
  std::vector<std::array<uint8_t, 3>> vertex_albedo;  // RGB8 albedo at each vertex
  int num_parts = 0;
};

struct SceneConfig {
  int num_figures = 1;
  int num_props = 1;
  bool empty_room = false;
};

class Scene {
 public:
  explicit Scene(const SceneConfig& config);

  const SceneTemplate& tmpl() const { return tmpl_; }
  // world_from_part of every part at time `t` seconds. Smooth in t.
  void PartPoses(double t, std::vector<Eigen::Isometry3f>* poses) const;
  // Posed vertex positions and normals (world) at time `t`.
  void Pose(double t, std::vector<Eigen::Vector3f>* positions, std::vector<Eigen::Vector3f>* normals,
            std::vector<Eigen::Isometry3f>* scratch_poses) const;
  // Moments of the animation in [t0, t1) that make a sound (a foot of the
  // first figure landing, the ball touching the floor), in time order.
  void SoundEvents(double t0, double t1, std::vector<std::pair<double, int>>* events) const;
  // world_from_head of figure `figure` at time `t`: origin at the centre of
  // the head, x forward (the face), y left, z up. Identity without figures.
  Eigen::Isometry3f HeadPose(double t, int figure) const;

 private:
  SceneConfig config_;
  SceneTemplate tmpl_;
  std::vector<int> part_owner_;  // object (figure or prop) of each part
};

// Linear RGB albedo in [0, 1] of a foreground material at texture coordinate `tex`.
Eigen::Vector3f Albedo(uint8_t material, uint8_t palette, const Eigen::Vector3f& tex);

// The static room: floor z = 0, walls at |x|, |y| = kRoomHalf, ceiling.
constexpr float kRoomHalf = 3.3f;
constexpr float kRoomHeight = 3.0f;
struct RoomHit {
  float t = 0;  // ray parameter (distance along a unit ray)
  Eigen::Vector3f normal;
  Eigen::Vector3f albedo;
};
// Intersects a ray starting inside the room with the room. Returns false if
// the origin is outside the room.
bool IntersectRoom(const Eigen::Vector3f& origin, const Eigen::Vector3f& dir, RoomHit* hit);

// The light: directional, from `LightDirection()` (unit, towards the light).
Eigen::Vector3f LightDirection();
constexpr float kAmbient = 0.38f;
constexpr float kDiffuse = 0.72f;

}  // namespace holo::studio
