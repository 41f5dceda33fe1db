// The desktop 3D view: one tree's GLB orbited with OrbitControls, its skeleton drawn over it as lines.
// The renderer is shared with VR mode (vr.js), which swaps in its own scene while a session runs.
import * as THREE from 'three';
import { GLTFLoader } from 'three/addons/loaders/GLTFLoader.js';
import { OrbitControls } from 'three/addons/controls/OrbitControls.js';

const loader = new GLTFLoader();

export function parseGLB(buffer) {
  return new Promise((resolve, reject) => loader.parse(buffer, '', resolve, reject));
}

// Skeleton arrays (Z up, metres) as line segments child -> parent in three's Y-up frame: (x, z, -y).
export function skeletonLines(skeleton) {
  const p = skeleton.positions, parent = skeleton.parent;
  const vertices = new Float32Array(Math.max(parent.length - 1, 0) * 6);
  let k = 0;
  for (let i = 1; i < parent.length; i++) {
    const j = parent[i];
    vertices.set([p[3 * i], p[3 * i + 2], -p[3 * i + 1], p[3 * j], p[3 * j + 2], -p[3 * j + 1]], k);
    k += 6;
  }
  const geometry = new THREE.BufferGeometry();
  geometry.setAttribute('position', new THREE.BufferAttribute(vertices, 3));
  const material = new THREE.LineBasicMaterial({ color: 0xff4fd8, depthTest: false, transparent: true, opacity: 0.8 });
  const lines = new THREE.LineSegments(geometry, material);
  lines.renderOrder = 1;
  return lines;
}

export function addLights(scene) {
  scene.add(new THREE.HemisphereLight(0xdfefff, 0x3a3020, 2.2));
  const sun = new THREE.DirectionalLight(0xffffff, 2.0);
  sun.position.set(4, 10, 6);
  scene.add(sun);
}

export class TreeViewer {
  constructor(container) {
    this.container = container;
    this.renderer = new THREE.WebGLRenderer({ antialias: true });
    this.renderer.setPixelRatio(Math.min(window.devicePixelRatio, 2));
    container.appendChild(this.renderer.domElement);
    this.scene = new THREE.Scene();
    this.scene.background = new THREE.Color(0x2b3440);
    addLights(this.scene);
    const ground = new THREE.Mesh(new THREE.CircleGeometry(1, 48), new THREE.MeshLambertMaterial({ color: 0x4a5a3a }));
    ground.rotation.x = -Math.PI / 2;
    this.ground = ground;
    this.scene.add(ground);
    this.camera = new THREE.PerspectiveCamera(40, 1, 0.01, 500);
    this.camera.position.set(4, 3, 6);
    this.controls = new OrbitControls(this.camera, this.renderer.domElement);
    this.controls.enableDamping = true;
    this.model = null;
    this.overlay = null;
    this.showSkeleton = true;
    this.loadSerial = 0;
    this.justLoaded = false;
    this.externalLoop = null;  // VR mode's frame function while a session runs
    new ResizeObserver(() => this.resize()).observe(container);
    this.resize();
    this.renderer.setAnimationLoop((time, frame) => this.frame(time, frame));
  }

  resize() {
    if (this.renderer.xr.isPresenting) return;
    const { clientWidth: w, clientHeight: h } = this.container;
    if (!w || !h) return;
    this.renderer.setSize(w, h, false);
    this.camera.aspect = w / h;
    this.camera.updateProjectionMatrix();
  }

  frame(time, xrFrame) {
    if (this.externalLoop) { this.externalLoop(time, xrFrame); return; }
    this.controls.update();
    this.renderer.render(this.scene, this.camera);
    if (this.justLoaded) {
      this.justLoaded = false;
      // The first frame with a tree in it: what the page-load benchmark waits for.
      if (window.firstTreeDrawnAt === undefined) window.firstTreeDrawnAt = performance.now();
      window.treesDrawn = (window.treesDrawn || 0) + 1;
    }
  }

  // Show a tree: GLB bytes and skeleton arrays; a later call wins over a slower earlier one.
  async show(buffer, skeleton) {
    const serial = ++this.loadSerial;
    const gltf = await parseGLB(buffer);
    if (serial !== this.loadSerial) return false;
    if (this.model) { this.scene.remove(this.model); disposeObject(this.model); }
    if (this.overlay) { this.scene.remove(this.overlay); disposeObject(this.overlay); }
    this.model = gltf.scene;
    this.scene.add(this.model);
    this.overlay = skeleton ? skeletonLines(skeleton) : null;
    if (this.overlay) { this.overlay.visible = this.showSkeleton; this.scene.add(this.overlay); }
    this.frameModel();
    this.justLoaded = true;
    return true;
  }

  setSkeletonVisible(visible) {
    this.showSkeleton = visible;
    if (this.overlay) this.overlay.visible = visible;
  }

  frameModel() {
    const box = new THREE.Box3().setFromObject(this.model);
    const size = box.getSize(new THREE.Vector3());
    const center = box.getCenter(new THREE.Vector3());
    const radius = Math.max(size.length() / 2, 0.05);
    const distance = radius / Math.sin(THREE.MathUtils.degToRad(this.camera.fov / 2)) * 1.05;
    this.controls.target.copy(center);
    this.camera.position.copy(center).add(new THREE.Vector3(0.6, 0.25, 1).normalize().multiplyScalar(distance));
    this.camera.near = distance / 100;
    this.camera.far = distance * 10;
    this.camera.updateProjectionMatrix();
    this.ground.scale.setScalar(Math.max(size.x, size.z) * 0.8 + 0.1);
    this.controls.update();
  }
}

export function disposeObject(object) {
  object.traverse((node) => {
    if (node.geometry) node.geometry.dispose();
    const materials = node.material ? (Array.isArray(node.material) ? node.material : [node.material]) : [];
    for (const material of materials) {
      for (const value of Object.values(material)) if (value && value.isTexture) value.dispose();
      material.dispose();
    }
  });
}
