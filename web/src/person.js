// Draws the remote site's mesh with three.js as the native renderer does
// (client/render/renderer.cc): per-vertex colour, unlit, no culling.

import * as THREE from 'three';

const VERTEX_VS = `
in vec3 position;
in vec3 color;
uniform mat4 modelViewMatrix;
uniform mat4 projectionMatrix;
out vec3 v_color;
void main() {
  v_color = color;
  gl_Position = projectionMatrix * (modelViewMatrix * vec4(position, 1.0));
}`;
const VERTEX_FS = `
precision highp float;
in vec3 v_color;
out vec4 o_color;
void main() { o_color = vec4(v_color, 1.0); }`;

export class PersonRenderer {
  constructor(parent, mode) {
    this.mode = mode === 'vertex' ? 'vertex' : 'vertex';
    this.parent = parent;
    this.geometry = new THREE.BufferGeometry();
    this.material = new THREE.RawShaderMaterial({
      glslVersion: THREE.GLSL3, vertexShader: VERTEX_VS, fragmentShader: VERTEX_FS, side: THREE.DoubleSide,
    });
    this.mesh = new THREE.Mesh(this.geometry, this.material);
    this.mesh.frustumCulled = false;
    parent.add(this.mesh);
    this.rig = null;
    this.frameIndex = -1;
  }

  setRig(rig) {
    this.rig = rig;
  }

  reset() {
    this.frameIndex = -1;
    this.mesh.visible = false;
  }

  setMesh(frameIndex, m) {
    const g = new THREE.BufferGeometry();
    g.setAttribute('position', new THREE.BufferAttribute(m.positions, 3));
    const nv = m.positions.length / 3;
    const colors = m.colors || new Uint8Array(nv * 3).fill(128);
    g.setAttribute('color', new THREE.BufferAttribute(colors, 3, true));
    if (m.normals) g.setAttribute('normal', new THREE.BufferAttribute(m.normals, 3));
    g.setIndex(new THREE.BufferAttribute(m.indices, 1));
    this.mesh.geometry = g;
    this.geometry.dispose();
    this.geometry = g;
    this.frameIndex = frameIndex;
    this.mesh.visible = true;
  }

  setPodImages(frameIndex, podIds, images) {
    this.podImages = { frameIndex, podIds, images };
  }

  // Called before each render (the projective mode's passes go here).
  prepare() {}
}
