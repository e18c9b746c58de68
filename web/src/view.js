// Camera conventions shared with the native renderer (client/render/view.cc):
// the world is Z up; a camera's intrinsics are FromFov (fx = fy = w / 2 /
// tan(hfov / 2), cx = (w − 1) / 2, cy = (h − 1) / 2) and its projection maps
// pixel centres exactly as ProjectionFromIntrinsics does. three.js cameras
// look down −z with y up, OpenCV cameras down +z with y down: the two
// differ by diag(1, −1, −1).

import * as THREE from 'three';

export function intrinsicsFromFov(width, height, hfovDeg) {
  const f = (0.5 * width) / Math.tan((0.5 * hfovDeg * Math.PI) / 180);
  return { width, height, fx: f, fy: f, cx: 0.5 * (width - 1), cy: 0.5 * (height - 1) };
}

// The native projection (OpenCV camera coordinates → clip), as a THREE.Matrix4
// for a three.js camera (its coordinates flipped to OpenCV's first).
export function projectionForThree(intr, near, far) {
  const { width: w, height: h, fx, fy, cx, cy } = intr;
  const p = new THREE.Matrix4().set(
    (2 * fx) / w, 0, (2 * (cx + 0.5)) / w - 1, 0,
    0, (-2 * fy) / h, 1 - (2 * (cy + 0.5)) / h, 0,
    0, 0, (far + near) / (far - near), (-2 * far * near) / (far - near),
    0, 0, 1, 0);
  return p.multiply(new THREE.Matrix4().makeScale(1, -1, -1));
}

// Sets `camera`'s projection to the native one for its current viewport.
export function applyNativeProjection(camera, width, height, hfovDeg, near = 0.02, far = 100) {
  const intr = intrinsicsFromFov(width, height, hfovDeg);
  camera.projectionMatrix.copy(projectionForThree(intr, near, far));
  camera.projectionMatrixInverse.copy(camera.projectionMatrix).invert();
  return intr;
}
