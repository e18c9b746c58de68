// Draws the remote site's mesh with three.js as the native renderer does
// (client/render/renderer.cc), in one of two modes:
//   * vertex: per-vertex colour, unlit;
//   * projective: the pods' colour images projected onto the mesh and
//     blended per fragment with Holoportation-style weights
//     w_i = max(0, n·d_i)^α · ((1 + d_i·d_eye) / 2)^β, each pod's visibility
//     from a depth map of the mesh rendered from that pod (texels near a
//     depth discontinuity used only when nothing clean is there), and the
//     pods' foreground masks down-weighting texels near the silhouette
//     (premultiplied into the texture). The shaders are the native ones,
//     ported to GLSL ES 3.00; same defaults (α = β = 2, 1.5 cm visibility
//     tolerance, 5 cm / 1 cm discontinuities, masks eroded 2 px and
//     feathered 2 px, edge floor 0.02, confidence 0.5).
// Back faces are not culled (as the native default).

import * as THREE from 'three';

const MAX_PODS = 16;
const OPTIONS = {
  alpha: 2, beta: 2, visTol: 0.015, jump: 0.05, radius: 0.01, edgeWeight: 0.001,
  erodePx: 2, featherPx: 2, edgeFloor: 0.02, minConfidence: 0.5,
};

const DISTORT_GLSL = `
vec2 Distort(vec2 x, vec4 d, float k3) {
  float r2 = dot(x, x);
  float radial = 1.0 + r2 * (d.x + r2 * (d.y + r2 * k3));
  return vec2(x.x * radial + 2.0 * d.z * x.x * x.y + d.w * (r2 + 2.0 * x.x * x.x),
              x.y * radial + d.z * (r2 + 2.0 * x.y * x.y) + 2.0 * d.w * x.x * x.y);
}`;

const DRAW_VS = `
precision highp float;
precision highp int;
#define MAX_PODS ${MAX_PODS}
in vec3 position;
in vec3 normal;
in vec3 color;
uniform mat4 modelViewMatrix;
uniform mat4 projectionMatrix;
uniform int u_mode;
uniform int u_num_pods;
uniform vec3 u_pod_center[MAX_PODS];
uniform vec3 u_eye_remote;
uniform float u_alpha;
uniform float u_beta;
out vec3 v_color;
out vec3 v_remote;
out vec4 v_w[MAX_PODS / 4];
invariant gl_Position;
float Pow(float x, float e) {
  if (e == 2.0) return x * x;
  if (e == 1.0) return x;
  if (e == 0.0) return 1.0;
  if (e == 4.0) return (x * x) * (x * x);
  return pow(x, e);
}
void main() {
  v_color = color;
  v_remote = position;
  gl_Position = projectionMatrix * (modelViewMatrix * vec4(position, 1.0));
  for (int k = 0; k < MAX_PODS / 4; ++k) v_w[k] = vec4(0.0);
  if (u_mode == 0) return;
  vec3 n = normalize(normal);
  vec3 to_eye = normalize(u_eye_remote - position);
  for (int i = 0; i < u_num_pods; ++i) {
    vec3 to_pod = normalize(u_pod_center[i] - position);
    float ndv = dot(n, to_pod);
    float w = ndv > 0.0 ? Pow(ndv, u_alpha) * Pow(max(0.5 * (1.0 + dot(to_pod, to_eye)), 1e-6), u_beta) : 0.0;
    v_w[i / 4][i % 4] = w;
  }
}`;

const DRAW_FS = `
precision highp float;
precision highp int;
precision highp sampler2DArray;
#define MAX_PODS ${MAX_PODS}
in vec3 v_color;
in vec3 v_remote;
in vec4 v_w[MAX_PODS / 4];
out vec4 o_color;
uniform int u_mode;
uniform mat4 u_pod_cam_from_world[MAX_PODS];
uniform int u_num_pods;
uniform vec4 u_pod_intr[MAX_PODS];
uniform vec4 u_pod_dist[MAX_PODS];
uniform float u_pod_k3[MAX_PODS];
uniform vec2 u_pod_size[MAX_PODS];
uniform vec2 u_array_size;
uniform sampler2DArray u_pod_color;
uniform sampler2DArray u_pod_depth;
uniform float u_vis_tol;
uniform float u_edge_weight;
uniform bool u_distorted;
uniform float u_min_confidence;
${DISTORT_GLSL}
void main() {
  if (u_mode == 0 || u_num_pods == 0) {
    o_color = vec4(v_color, 1.0);
    return;
  }
  vec3 acc = vec3(0.0);
  float acc_w = 0.0, sum_w = 0.0;
  for (int i = 0; i < u_num_pods; ++i) {
    float w = v_w[i / 4][i % 4];
    if (w <= 1e-6) continue;
    vec3 pod = (u_pod_cam_from_world[i] * vec4(v_remote, 1.0)).xyz;
    if (pod.z < 0.05) continue;
    vec2 px = pod.xy / pod.z;
    if (u_distorted) {
      vec2 xn = Distort(px, u_pod_dist[i], u_pod_k3[i]);
      vec4 intr = u_pod_intr[i];
      px = vec2(intr.x * xn.x + intr.z, intr.y * xn.y + intr.w);
    }
    vec2 size = u_pod_size[i];
    if (px.x < -0.5 || px.y < -0.5 || px.x >= size.x - 0.5 || px.y >= size.y - 0.5) continue;
    float zf = texelFetch(u_pod_depth, ivec3(ivec2(floor(px + 0.5)), i), 0).r;
    float zmap = abs(zf);
    if (zmap <= 0.0 || pod.z > zmap + u_vis_tol) continue;
    vec4 c = texture(u_pod_color, vec3((px + 0.5) / u_array_size, float(i)));
    float k = zf < 0.0 ? u_edge_weight * w : w;
    acc += k * c.rgb;
    acc_w += k * c.a;
    sum_w += k;
  }
  if (acc_w > 0.0) {
    float confidence = acc_w / sum_w;
    o_color = vec4(mix(v_color, acc / acc_w, smoothstep(0.0, u_min_confidence, confidence)), 1.0);
  } else {
    o_color = vec4(v_color, 1.0);
  }
}`;

const DEPTH_VS = `
precision highp float;
precision highp int;
in vec3 position;
uniform mat4 u_cam_from_world;
uniform vec4 u_intr;
uniform vec4 u_dist;
uniform float u_k3;
uniform vec2 u_size;
uniform float u_near;
uniform float u_far;
out float v_z;
${DISTORT_GLSL}
void main() {
  vec4 pc = u_cam_from_world * vec4(position, 1.0);
  float z = pc.z;
  v_z = z;
  vec2 xn = Distort(pc.xy / max(z, 1e-6), u_dist, u_k3);
  vec2 px = vec2(u_intr.x * xn.x + u_intr.z, u_intr.y * xn.y + u_intr.w);
  vec2 ndc = 2.0 * (px + 0.5) / u_size - 1.0;
  float zc = (u_far + u_near) / (u_far - u_near) * z - 2.0 * u_far * u_near / (u_far - u_near);
  gl_Position = z > u_near ? vec4(ndc * z, zc, z) : vec4(0.0, 0.0, -2.0, 1.0);
}`;
const DEPTH_FS = `
precision highp float;
precision highp int;
in float v_z;
out vec4 o_z;
void main() { o_z = vec4(v_z, 0.0, 0.0, 1.0); }`;

const EDGE_VS = `
precision highp float;
precision highp int;
in vec3 position;
void main() { gl_Position = vec4(position.xy, 0.0, 1.0); }`;
const EDGE_FS = `
precision highp float;
precision highp int;
precision highp sampler2DArray;
uniform sampler2DArray u_depth;
uniform int u_layer;
uniform vec2 u_size;
uniform float u_fx;
uniform float u_jump;
uniform float u_radius;
out vec4 o_z;
void main() {
  ivec2 ip = ivec2(gl_FragCoord.xy);
  float z = texelFetch(u_depth, ivec3(ip, u_layer), 0).r;
  if (z <= 0.0) {
    o_z = vec4(0.0);
    return;
  }
  ivec2 kOffsets[8] = ivec2[8](ivec2(-1, 0), ivec2(1, 0), ivec2(0, -1), ivec2(0, 1),
                               ivec2(-1, -1), ivec2(1, 1), ivec2(-1, 1), ivec2(1, -1));
  int r = clamp(int(ceil(u_radius * u_fx / z)), 1, 8);
  ivec2 maxp = ivec2(u_size) - 1;
  bool near_edge = false;
  for (int k = 0; k < 8; ++k) {
    float zq = texelFetch(u_depth, ivec3(clamp(ip + kOffsets[k] * r, ivec2(0), maxp), u_layer), 0).r;
    if (zq <= 0.0 || abs(zq - z) > u_jump) near_edge = true;
  }
  o_z = vec4(near_edge ? -z : z, 0.0, 0.0, 1.0);
}`;

// 4x4 (THREE.Matrix4) of a pose34 {R row-major, t}.
function poseMatrix(p) {
  const R = p.R, t = p.t;
  return new THREE.Matrix4().set(R[0], R[1], R[2], t[0], R[3], R[4], R[5], t[1], R[6], R[7], R[8], t[2], 0, 0, 0, 1);
}

// Premultiplied RGBA of a decoded colour image: the mask weight (chessboard
// distance to the background, eroded and feathered) in alpha, as the native
// renderer's UploadPodTextures.
function maskWeighted(img, out, o = OPTIONS) {
  const { width: w, height: h, rgba } = img;
  const d = new Uint8Array(w * h);
  for (let y = 0; y < h; ++y) {
    for (let x = 0; x < w; ++x) {
      const k = y * w + x;
      if (rgba[4 * k + 3] === 0) {
        d[k] = 0;
        continue;
      }
      let v = 1;
      if (x > 0 && y > 0) v = Math.min(d[k - 1], d[k - w], d[k - w - 1], x + 1 < w ? d[k - w + 1] : 0) + 1;
      d[k] = Math.min(v, 255);
    }
  }
  for (let y = h - 1; y >= 0; --y) {
    for (let x = w - 1; x >= 0; --x) {
      const k = y * w + x;
      if (d[k] === 0) continue;
      let v = 1;
      if (x + 1 < w && y + 1 < h) v = Math.min(d[k + 1], d[k + w], d[k + w + 1], x > 0 ? d[k + w - 1] : 0) + 1;
      d[k] = Math.min(d[k], v);
    }
  }
  const lut = new Uint8Array(256);
  for (let k = 1; k < 256; ++k) {
    const f = Math.fround;
    const ramp = o.featherPx > 0 ? f(f(k - o.erodePx) / o.featherPx) : k > o.erodePx ? 1 : 0;
    const wgt = Math.min(1, Math.max(f(o.edgeFloor), ramp));
    lut[k] = Math.round(f(wgt * 255)) || 1;
  }
  for (let k = 0; k < w * h; ++k) {
    const a = lut[d[k]];
    out[4 * k] = Math.floor((rgba[4 * k] * a + 127) / 255);
    out[4 * k + 1] = Math.floor((rgba[4 * k + 1] * a + 127) / 255);
    out[4 * k + 2] = Math.floor((rgba[4 * k + 2] * a + 127) / 255);
    out[4 * k + 3] = a;
  }
}

// What to do with the pods' colour images of frame `imagesFrame` when the
// mesh shown is `meshFrame` and the images shown (if any) are of
// `shownFrame` (-1: none): 'apply' them to the mesh shown, 'hold' them for
// their own mesh (they came first), or 'drop' them (older than what is shown).
// Colour of an older mesh is applied: a live stream's video colour decodes
// slower than its geometry (8 pods of V1: ~110 ms a frame in Chromium here),
// so a rule of exact frames only would never colour a person who gets a new
// mesh every frame; the newest colour there is beats none, as the native
// viewer keeps its last images for a mesh whose colour has not come.
export function colourAction(meshFrame, imagesFrame, shownFrame) {
  if (imagesFrame === meshFrame) return 'apply';
  if (imagesFrame > meshFrame) return 'hold';
  return imagesFrame > shownFrame ? 'apply' : 'drop';
}

export class PersonRenderer {
  constructor(parent, mode) {
    this.mode = mode === 'vertex' ? 'vertex' : 'projective';
    this.parent = parent;
    this.geometry = new THREE.BufferGeometry();
    this.uniforms = {
      u_mode: { value: 0 }, u_num_pods: { value: 0 },
      u_pod_center: { value: Array.from({ length: MAX_PODS }, () => new THREE.Vector3()) },
      u_eye_remote: { value: new THREE.Vector3() },
      u_alpha: { value: OPTIONS.alpha }, u_beta: { value: OPTIONS.beta },
      u_pod_cam_from_world: { value: Array.from({ length: MAX_PODS }, () => new THREE.Matrix4()) },
      u_pod_intr: { value: Array.from({ length: MAX_PODS }, () => new THREE.Vector4()) },
      u_pod_dist: { value: Array.from({ length: MAX_PODS }, () => new THREE.Vector4()) },
      u_pod_k3: { value: new Array(MAX_PODS).fill(0) },
      u_pod_size: { value: Array.from({ length: MAX_PODS }, () => new THREE.Vector2()) },
      u_array_size: { value: new THREE.Vector2(1, 1) },
      u_pod_color: { value: null }, u_pod_depth: { value: null },
      u_vis_tol: { value: OPTIONS.visTol }, u_edge_weight: { value: OPTIONS.edgeWeight },
      u_distorted: { value: false }, u_min_confidence: { value: OPTIONS.minConfidence },
    };
    this.material = new THREE.RawShaderMaterial({
      glslVersion: THREE.GLSL3, vertexShader: DRAW_VS, fragmentShader: DRAW_FS, side: THREE.DoubleSide,
      uniforms: this.uniforms,
    });
    this.mesh = new THREE.Mesh(this.geometry, this.material);
    this.mesh.frustumCulled = false;
    this.mesh.visible = false;
    parent.add(this.mesh);
    this.rig = null;
    this.frameIndex = -1;
    this.pods = null;
    this.visibilityDirty = true;
    this.haveImages = false;
    this.pendingImages = null;
  }

  setRig(rig) {
    this.rig = rig;
    const pods = rig.pods.slice(0, MAX_PODS).map((p) => {
      // world_from_color = world_from_depth · color_from_depth⁻¹
      const worldFromColor = poseMatrix(p.worldFromDepth).multiply(poseMatrix(p.colorFromDepth).invert());
      const camFromWorld = worldFromColor.clone().invert();
      const center = new THREE.Vector3().setFromMatrixPosition(worldFromColor);
      return { id: p.id, intr: p.color, camFromWorld, center };
    });
    this.pods = pods;
    const n = pods.length;
    const w = Math.max(...pods.map((p) => p.intr.width)), h = Math.max(...pods.map((p) => p.intr.height));
    const distorted = pods.some((p) => p.intr.distortion.some((d) => d !== 0));
    const u = this.uniforms;
    u.u_num_pods.value = n;
    u.u_distorted.value = distorted;
    u.u_array_size.value.set(w, h);
    pods.forEach((p, i) => {
      let m = p.camFromWorld.clone();
      if (!distorted) {
        const k = new THREE.Matrix4().set(p.intr.fx, 0, p.intr.cx, 0, 0, p.intr.fy, p.intr.cy, 0, 0, 0, 1, 0, 0, 0, 0, 1);
        m = k.multiply(m);
      }
      u.u_pod_cam_from_world.value[i].copy(m);
      u.u_pod_intr.value[i].set(p.intr.fx, p.intr.fy, p.intr.cx, p.intr.cy);
      u.u_pod_dist.value[i].set(...p.intr.distortion.slice(0, 4));
      u.u_pod_k3.value[i] = p.intr.distortion[4];
      u.u_pod_size.value[i].set(p.intr.width, p.intr.height);
      u.u_pod_center.value[i].copy(p.center);
    });
    if (!this.arrayW || this.arrayW !== w || this.arrayH !== h || this.arrayN !== n) {
      this.disposeTargets();
      const opts = { type: THREE.FloatType, format: THREE.RedFormat, minFilter: THREE.NearestFilter,
        magFilter: THREE.NearestFilter, depthBuffer: true, generateMipmaps: false };
      this.rawTarget = new THREE.WebGLArrayRenderTarget(w, h, n, opts);
      this.flagTarget = new THREE.WebGLArrayRenderTarget(w, h, n, { ...opts, depthBuffer: false });
      this.colorData = new Uint8Array(w * h * n * 4);
      this.colorTex = new THREE.DataArrayTexture(this.colorData, w, h, n);
      this.colorTex.format = THREE.RGBAFormat;
      this.colorTex.type = THREE.UnsignedByteType;
      this.colorTex.minFilter = THREE.LinearFilter;
      this.colorTex.magFilter = THREE.LinearFilter;
      this.colorTex.generateMipmaps = false;
      this.colorTex.unpackAlignment = 1;
      this.colorTex.colorSpace = THREE.NoColorSpace;
      this.arrayW = w;
      this.arrayH = h;
      this.arrayN = n;
    }
    u.u_pod_color.value = this.colorTex;
    u.u_pod_depth.value = this.flagTarget.texture;
    this.haveImages = false;
    this.visibilityDirty = true;
    this.depthMaterial = this.depthMaterial || new THREE.RawShaderMaterial({
      glslVersion: THREE.GLSL3, vertexShader: DEPTH_VS, fragmentShader: DEPTH_FS, side: THREE.DoubleSide,
      uniforms: { u_cam_from_world: { value: new THREE.Matrix4() }, u_intr: { value: new THREE.Vector4() },
        u_dist: { value: new THREE.Vector4() }, u_k3: { value: 0 }, u_size: { value: new THREE.Vector2() },
        u_near: { value: 0.05 }, u_far: { value: 100 } },
    });
    this.edgeMaterial = this.edgeMaterial || new THREE.RawShaderMaterial({
      glslVersion: THREE.GLSL3, vertexShader: EDGE_VS, fragmentShader: EDGE_FS, depthTest: false, depthWrite: false,
      uniforms: { u_depth: { value: null }, u_layer: { value: 0 }, u_size: { value: new THREE.Vector2() },
        u_fx: { value: 0 }, u_jump: { value: OPTIONS.jump }, u_radius: { value: OPTIONS.radius } },
    });
  }

  disposeTargets() {
    if (this.rawTarget) this.rawTarget.dispose();
    if (this.flagTarget) this.flagTarget.dispose();
    if (this.colorTex) this.colorTex.dispose();
  }

  reset() {
    this.frameIndex = -1;
    this.mesh.visible = false;
    this.haveImages = false;
    this.onChange();
  }

  setMesh(frameIndex, m) {
    const g = new THREE.BufferGeometry();
    g.setAttribute('position', new THREE.BufferAttribute(m.positions, 3));
    const nv = m.positions.length / 3;
    g.setAttribute('color', new THREE.BufferAttribute(m.colors || new Uint8Array(nv * 3).fill(128), 3, true));
    if (!m.normals) {
      g.setIndex(new THREE.BufferAttribute(m.indices, 1));
      g.computeVertexNormals();
    } else {
      g.setAttribute('normal', new THREE.BufferAttribute(m.normals, 3));
      g.setIndex(new THREE.BufferAttribute(m.indices, 1));
    }
    this.mesh.geometry = g;
    this.geometry.dispose();
    this.geometry = g;
    this.frameIndex = frameIndex;
    this.mesh.visible = true;
    this.visibilityDirty = true;
    this.onChange();
    // Colour images of this frame (or of a frame this mesh replaced) that came first.
    if (this.pendingImages) {
      const action = colourAction(frameIndex, this.pendingImages.frameIndex, this.shownImagesFrame());
      if (action === 'apply') this.applyImages(this.pendingImages);
      else if (action === 'drop') this.pendingImages = null;
    }
  }

  // Decoded colour images of frame `frameIndex` (one per pod id).
  setPodImages(frameIndex, podIds, images) {
    if (this.mode !== 'projective' || !this.pods) return;
    const set = { frameIndex, podIds, images };
    // Images belong to their mesh: held until that frame is shown, or shown
    // on a newer mesh when theirs has already been replaced (colourAction).
    const action = colourAction(this.frameIndex, frameIndex, this.shownImagesFrame());
    if (action === 'hold') this.pendingImages = set;
    else if (action === 'apply') this.applyImages(set);
  }

  shownImagesFrame() {
    return this.haveImages ? this.imagesFrame : -1;
  }

  applyImages({ frameIndex, podIds, images }) {
    const n = this.pods.length, w = this.arrayW, h = this.arrayH;
    for (let i = 0; i < n; ++i) {
      const k = podIds.indexOf(this.pods[i].id);
      const img = k >= 0 ? images[k] : null;
      if (!img || img.width !== this.pods[i].intr.width || img.height !== this.pods[i].intr.height) return;
    }
    const layer = new Uint8Array(w * h * 4);
    for (let i = 0; i < n; ++i) {
      const img = images[podIds.indexOf(this.pods[i].id)];
      if (img.width === w && img.height === h) {
        maskWeighted(img, this.colorData.subarray(i * w * h * 4, (i + 1) * w * h * 4));
      } else {
        maskWeighted(img, layer);
        const dst = this.colorData.subarray(i * w * h * 4, (i + 1) * w * h * 4);
        dst.fill(0);
        for (let y = 0; y < img.height; ++y) dst.set(layer.subarray(y * img.width * 4, (y + 1) * img.width * 4), y * w * 4);
      }
    }
    this.colorTex.needsUpdate = true;
    this.haveImages = true;
    this.imagesFrame = frameIndex;
    this.onChange();
    if (this.pendingImages && this.pendingImages.frameIndex <= frameIndex) this.pendingImages = null;
  }

  // The pods' depth maps and discontinuity flags for the current mesh.
  updateVisibility(renderer) {
    const old = renderer.getRenderTarget();
    const oldClear = renderer.getClearColor(new THREE.Color()), oldAlpha = renderer.getClearAlpha();
    const xr = renderer.xr.enabled;
    renderer.xr.enabled = false;
    renderer.setClearColor(0x000000, 0);
    const cam = new THREE.Camera();
    const depthScene = new THREE.Scene();
    const depthMesh = new THREE.Mesh(this.geometry, this.depthMaterial);
    depthMesh.frustumCulled = false;
    depthScene.add(depthMesh);
    const du = this.depthMaterial.uniforms;
    this.pods.forEach((p, i) => {
      du.u_cam_from_world.value.copy(p.camFromWorld);
      du.u_intr.value.set(p.intr.fx, p.intr.fy, p.intr.cx, p.intr.cy);
      du.u_dist.value.set(...p.intr.distortion.slice(0, 4));
      du.u_k3.value = p.intr.distortion[4];
      du.u_size.value.set(p.intr.width, p.intr.height);
      this.rawTarget.viewport.set(0, 0, this.arrayW, this.arrayH);
      renderer.setRenderTarget(this.rawTarget, i);
      renderer.clear(true, true, false);
      this.rawTarget.viewport.set(0, 0, p.intr.width, p.intr.height);
      renderer.setRenderTarget(this.rawTarget, i);
      renderer.render(depthScene, cam);
    });
    const edgeScene = new THREE.Scene();
    const tri = new THREE.BufferGeometry();
    tri.setAttribute('position', new THREE.BufferAttribute(new Float32Array([-1, -1, 0, 3, -1, 0, -1, 3, 0]), 3));
    const edgeMesh = new THREE.Mesh(tri, this.edgeMaterial);
    edgeMesh.frustumCulled = false;
    edgeScene.add(edgeMesh);
    const eu = this.edgeMaterial.uniforms;
    eu.u_depth.value = this.rawTarget.texture;
    this.pods.forEach((p, i) => {
      eu.u_layer.value = i;
      eu.u_size.value.set(p.intr.width, p.intr.height);
      eu.u_fx.value = p.intr.fx;
      this.flagTarget.viewport.set(0, 0, this.arrayW, this.arrayH);
      renderer.setRenderTarget(this.flagTarget, i);
      renderer.clear(true, false, false);
      this.flagTarget.viewport.set(0, 0, p.intr.width, p.intr.height);
      renderer.setRenderTarget(this.flagTarget, i);
      renderer.render(edgeScene, cam);
    });
    tri.dispose();
    renderer.setRenderTarget(old);
    renderer.setClearColor(oldClear, oldAlpha);
    renderer.xr.enabled = xr;
    this.visibilityDirty = false;
  }

  // Before each render: the visibility pass when the mesh changed, the eye.
  prepare(renderer, camera) {
    const projective = this.mode === 'projective' && this.pods && this.haveImages && this.mesh.visible;
    this.uniforms.u_mode.value = projective ? 1 : 0;
    if (!projective) return;
    if (this.visibilityDirty) this.updateVisibility(renderer);
    const eye = new THREE.Vector3().setFromMatrixPosition(camera.matrixWorld);
    this.uniforms.u_eye_remote.value.copy(this.parent.worldToLocal(eye));
  }
}
