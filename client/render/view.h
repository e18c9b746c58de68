// Viewer cameras: OpenGL matrices from the project's camera model (pinhole
// intrinsics, OpenCV axes: x right, y down, z forward; pixel centres at
// integer coordinates), the interactive orbit/fly controller, the mosaic of
// K horizontally spaced views (light-field display input) and the miniature
// ("room on a table top") placement.
#pragma once

#include <vector>

#include <Eigen/Core>
#include <Eigen/Geometry>

#include "common/camera.h"
#include "common/pose.h"
#include "common/status.h"

namespace holo::render {

// Clip-from-camera matrix for `intr` (distortion ignored): a point projecting
// to pixel (u, v) lands on the centre of pixel (u, v) of a viewport of
// intr.width × intr.height, row 0 at the top of the image (so glReadPixels
// rows come out bottom-up). Depth range [near_m, far_m].
Eigen::Matrix4f ProjectionFromIntrinsics(const Intrinsics& intr, float near_m, float far_m);
// Clip-from-world = projection · camera_from_world.
Eigen::Matrix4f ViewProjection(const CameraModel& camera, float near_m, float far_m);

// Free-viewpoint camera: orbit around a target (mouse drag turns, wheel
// zooms) or fly (WASD moves, mouse looks). World is z-up.
class CameraController {
 public:
  enum class Mode { kOrbit, kFly };

  // Orbit: eye on a sphere of `distance_m` around `target`, at `yaw_deg`
  // (from +x towards +y) and `pitch_deg` (up from horizontal).
  void SetOrbit(const Eigen::Vector3f& target, float distance_m, float yaw_deg, float pitch_deg);
  void SetMode(Mode m);
  Mode mode() const { return mode_; }

  // Mouse drag in pixels: orbit turns around the target; fly turns the head.
  void Rotate(float dx_px, float dy_px);
  // Mouse wheel: orbit changes the distance (×0.9 per step), fly moves forward.
  void Zoom(float steps);
  // Keyboard motion in metres along the view's forward, right and world up.
  void Move(float forward_m, float right_m, float up_m);

  // world_from_camera of the current view.
  Pose WorldFromCamera() const;
  Eigen::Vector3f Eye() const;
  Eigen::Vector3f Target() const { return target_; }

 private:
  Eigen::Vector3f Forward() const;
  Mode mode_ = Mode::kOrbit;
  Eigen::Vector3f target_ = Eigen::Vector3f(0, 0, 1);
  Eigen::Vector3f eye_ = Eigen::Vector3f(2.5f, 0, 1.6f);  // fly mode position
  float distance_ = 2.5f, yaw_deg_ = 0, pitch_deg_ = 10;
};

// Grid of K tiles filling a width × height image: cols = ceil(sqrt(K)),
// rows = ceil(K / cols); tile (i % cols, i / cols), left to right, top to bottom.
struct MosaicLayout {
  int views = 1, cols = 1, rows = 1;
  int tile_width = 0, tile_height = 0;
  // Top-left pixel of tile i.
  int TileX(int i) const { return (i % cols) * tile_width; }
  int TileY(int i) const { return (i / cols) * tile_height; }
};
StatusOr<MosaicLayout> MakeMosaicLayout(int views, int width, int height);

struct MosaicOptions {
  // Distance between neighbouring views along the camera's x axis, metres.
  float spacing_m = 0.04f;
  // Distance (camera z) of the plane every view converges on: a point there
  // lands on the same pixel in every tile (off-axis frusta, as light-field
  // displays expect; no toe-in).
  float convergence_m = 2.5f;
  // Horizontal field of view of every tile, degrees.
  float hfov_deg = 60.0f;
};

// K cameras, view 0 leftmost, centred on `center` (world_from_camera of the
// middle), each with the tile's intrinsics and its principal point shifted
// so that the views converge at options.convergence_m.
std::vector<CameraModel> MosaicCameras(const Pose& center, const MosaicLayout& layout, const MosaicOptions& options);

// Miniature mode: the remote room scaled by `scale` about `pivot` (a point of
// the remote room, usually the floor under the people) and placed with the
// pivot at `position` in the local room, turned by `yaw_deg` about z.
struct Miniature {
  float scale = 1.0f;
  Eigen::Vector3f pivot = Eigen::Vector3f::Zero();
  Eigen::Vector3f position = Eigen::Vector3f::Zero();
  float yaw_deg = 0;
  Status Check() const;
  // local_from_remote as a similarity transform (4×4).
  Eigen::Matrix4f LocalFromRemote() const;
};

}  // namespace holo::render
