// VR mode (WebXR immersive-vr): the page's trees in a ring around the reviewer, a controller ray to pick one,
// squeeze to grab (turn with the hand; a second hand or the thumbstick scales), a panel with verdict buttons.
import * as THREE from 'three';
import * as api from './api.js';
import { addLights, disposeObject, parseGLB } from './viewer.js';

const RING_RADIUS_M = 2.6;
const TREE_HEIGHT_M = 1.7;
const PANEL_W = 800, PANEL_H = 440;
// Panel buttons in canvas pixels: [name, label, x, y, w, h, colour].
const BUTTONS = [['approve', 'Approve', 30, 300, 230, 110, '#2e7d32'], ['reject', 'Reject', 285, 300, 230, 110, '#b71c1c'],
                 ['previous', '◀ page', 540, 300, 110, 110, '#39424e'], ['next', 'page ▶', 660, 300, 110, 110, '#39424e']];

// A flat panel drawn from a canvas (widthPx x heightPx) as a mesh `metres` wide: {canvas, texture, mesh}; draw on
// the canvas, then set texture.needsUpdate. The modelling page's tool menu is one too.
export function canvasPanel(widthPx, heightPx, metres) {
  const canvas = document.createElement('canvas');
  canvas.width = widthPx;
  canvas.height = heightPx;
  const texture = new THREE.CanvasTexture(canvas);
  texture.colorSpace = THREE.SRGBColorSpace;
  const mesh = new THREE.Mesh(new THREE.PlaneGeometry(metres, metres * heightPx / widthPx),
                              new THREE.MeshBasicMaterial({ map: texture }));
  return { canvas, texture, mesh };
}

// A controller's pointing ray, `length` metres along its -z (the modelling page's controllers have one too).
export function controllerRay(length) {
  const ray = new THREE.Line(new THREE.BufferGeometry().setFromPoints([new THREE.Vector3(), new THREE.Vector3(0, 0, -1)]),
                             new THREE.LineBasicMaterial({ color: 0x9fd3ff }));
  ray.scale.z = length;
  return ray;
}

export class VRMode {
  constructor(viewer, callbacks) {
    this.viewer = viewer;
    this.callbacks = callbacks;
    this.session = null;
    this.treeGroups = [];
    this.selected = null;
    this.grabs = new Map();  // controller -> tree group it holds
    this.raycaster = new THREE.Raycaster();
    window.reviewVR = this;
  }

  async supported() {
    if (!('xr' in navigator) || !navigator.xr) return false;
    try { return await navigator.xr.isSessionSupported('immersive-vr'); } catch (_) { return false; }
  }

  async enter(trees) {
    const session = await navigator.xr.requestSession('immersive-vr', { optionalFeatures: ['local-floor'] });
    const renderer = this.viewer.renderer;
    const floor = !session.enabledFeatures || session.enabledFeatures.includes('local-floor');
    renderer.xr.setReferenceSpaceType(floor ? 'local-floor' : 'local');
    renderer.xr.enabled = true;
    this.buildScene();
    session.addEventListener('end', () => this.exit());
    await renderer.xr.setSession(session);
    this.session = session;
    this.viewer.externalLoop = (time, frame) => this.frame(time, frame);
    this.callbacks.modeChanged('vr');
    await this.layout(trees);
    this.state = 'presenting';
  }

  exit() {
    if (!this.session) return;
    this.session = null;
    this.viewer.externalLoop = null;
    this.viewer.renderer.xr.enabled = false;
    this.clearTrees();
    disposeObject(this.scene);
    this.scene = null;
    this.state = 'ended';
    this.callbacks.modeChanged('desktop');
    this.viewer.resize();
  }

  buildScene() {
    this.scene = new THREE.Scene();
    this.scene.background = new THREE.Color(0x1d2530);
    addLights(this.scene);
    const floor = new THREE.Mesh(new THREE.CircleGeometry(RING_RADIUS_M + 1.5, 64), new THREE.MeshLambertMaterial({ color: 0x39452f }));
    floor.rotation.x = -Math.PI / 2;
    this.scene.add(floor);
    this.root = new THREE.Group();
    this.scene.add(this.root);
    ({ canvas: this.panelCanvas, texture: this.panelTexture, mesh: this.panel } = canvasPanel(PANEL_W, PANEL_H, 0.8));
    this.panel.position.set(0, 1.0, -0.8);
    this.panel.rotation.x = -0.5;
    this.scene.add(this.panel);
    this.controllers = [0, 1].map((i) => this.makeController(i));
    this.drawPanel();
  }

  makeController(i) {
    const controller = this.viewer.renderer.xr.getController(i);
    const ray = controllerRay(5);
    controller.add(ray);
    controller.add(new THREE.Mesh(new THREE.BoxGeometry(0.03, 0.03, 0.1), new THREE.MeshLambertMaterial({ color: 0x8899aa })));
    controller.userData.ray = ray;
    controller.addEventListener('connected', (event) => { controller.userData.gamepad = event.data.gamepad; });
    controller.addEventListener('disconnected', () => { controller.userData.gamepad = null; this.release(controller); });
    controller.addEventListener('selectstart', () => this.pick(controller));
    controller.addEventListener('squeezestart', () => this.grab(controller));
    controller.addEventListener('squeezeend', () => this.release(controller));
    this.scene.add(controller);
    return controller;
  }

  // Lay the trees of the current page around the reviewer, each scaled to TREE_HEIGHT_M on its own base ring.
  async layout(trees) {
    if (!this.scene) return;
    this.clearTrees();
    const n = Math.max(trees.length, 1);
    const groups = trees.map((entry, i) => {
      const angle = Math.PI + (2 * Math.PI * i) / n;  // the first tree straight ahead (-z)
      const group = new THREE.Group();
      group.position.set(RING_RADIUS_M * Math.sin(angle), 0, RING_RADIUS_M * Math.cos(angle));
      group.lookAt(0, 0, 0);
      group.userData = { treeId: entry.tree_id, entry };
      const base = new THREE.Mesh(new THREE.RingGeometry(0.35, 0.45, 40), new THREE.MeshBasicMaterial({ color: 0x55606c }));
      base.rotation.x = -Math.PI / 2;
      base.position.y = 0.01;
      group.add(base);
      group.userData.base = base;
      this.root.add(group);
      this.paintBase(group);
      return group;
    });
    this.treeGroups = groups;
    await Promise.all(groups.map((group) => this.loadTree(group)));
    this.selected = groups[0] || null;
    groups.forEach((g) => this.paintBase(g));
    this.drawPanel();
  }

  async loadTree(group) {
    if (group.userData.entry.error) return;
    const gltf = await parseGLB(await api.glb(group.userData.treeId));
    if (!this.scene || !this.treeGroups.includes(group)) { disposeObject(gltf.scene); return; }
    const model = gltf.scene;
    const box = new THREE.Box3().setFromObject(model);
    const size = box.getSize(new THREE.Vector3());
    const scale = TREE_HEIGHT_M / Math.max(size.y, 1e-3);
    model.scale.setScalar(scale);
    model.position.y = -box.min.y * scale;
    group.add(model);
    // An invisible box to pick and grab: cheaper and steadier than the leaves.
    const hit = new THREE.Mesh(new THREE.BoxGeometry(Math.max(size.x, size.z) * scale, TREE_HEIGHT_M, Math.max(size.x, size.z) * scale),
                               new THREE.MeshBasicMaterial({ transparent: true, opacity: 0, depthWrite: false }));
    hit.position.y = TREE_HEIGHT_M / 2;
    hit.userData.group = group;
    group.add(hit);
    group.userData.hit = hit;
  }

  clearTrees() {
    for (const group of this.treeGroups) { group.parent?.remove(group); disposeObject(group); }
    this.treeGroups = [];
    this.selected = null;
    this.grabs.clear();
  }

  paintBase(group) {
    const verdict = group.userData.entry.mine;
    const colour = group === this.selected ? 0x58a6ff : verdict === 'approve' ? 0x2e7d32 : verdict === 'reject' ? 0xb71c1c : 0x55606c;
    group.userData.base.material.color.setHex(colour);
  }

  aim(controller) {
    const rotation = new THREE.Matrix4().extractRotation(controller.matrixWorld);
    this.raycaster.ray.origin.setFromMatrixPosition(controller.matrixWorld);
    this.raycaster.ray.direction.set(0, 0, -1).applyMatrix4(rotation);
    const targets = [this.panel, ...this.treeGroups.map((g) => g.userData.hit).filter(Boolean)];
    return this.raycaster.intersectObjects(targets, false)[0] || null;
  }

  pick(controller) {
    const hit = this.aim(controller);
    if (!hit) return;
    if (hit.object === this.panel) {
      const x = hit.uv.x * PANEL_W, y = (1 - hit.uv.y) * PANEL_H;
      const button = BUTTONS.find(([, , bx, by, bw, bh]) => x >= bx && x <= bx + bw && y >= by && y <= by + bh);
      if (button) this.press(button[0]);
    } else this.selectTree(hit.object.userData.group.userData.treeId);
  }

  selectTree(treeId) {
    const previous = this.selected;
    this.selected = this.treeGroups.find((g) => g.userData.treeId === treeId) || null;
    if (previous) this.paintBase(previous);
    if (this.selected) this.paintBase(this.selected);
    this.drawPanel();
  }

  // A panel button: a verdict on the selected tree, or another page of trees.
  async press(name) {
    if (name === 'previous' || name === 'next') return this.callbacks.page(name === 'next' ? 1 : -1);
    const group = this.selected;
    if (!group) return;
    await this.callbacks.verdict(name, group.userData.treeId);
    group.userData.entry.mine = name;
    this.paintBase(group);
    this.drawPanel();
  }

  grab(controller) {
    const hit = this.aim(controller);
    if (!hit || hit.object === this.panel) return;
    const group = hit.object.userData.group;
    const other = [...this.grabs.entries()].find(([c, g]) => g === group && c !== controller);
    if (other) {  // second hand on the same tree: scale by the change of distance between the hands
      this.scaling = { group, hands: [other[0], controller], distance: this.handDistance(other[0], controller), scale: group.scale.x };
      return;
    }
    controller.attach(group);
    this.grabs.set(controller, group);
    this.selectTree(group.userData.treeId);
  }

  release(controller) {
    if (this.scaling && this.scaling.hands.includes(controller)) this.scaling = null;
    const group = this.grabs.get(controller);
    if (group && this.root) this.root.attach(group);
    this.grabs.delete(controller);
  }

  handDistance(a, b) {
    return new THREE.Vector3().setFromMatrixPosition(a.matrixWorld).distanceTo(new THREE.Vector3().setFromMatrixPosition(b.matrixWorld));
  }

  frame() {
    if (this.scaling) {
      const { group, hands, distance, scale } = this.scaling;
      group.scale.setScalar(THREE.MathUtils.clamp(scale * this.handDistance(...hands) / Math.max(distance, 1e-3), 0.1, 10));
    }
    for (const [controller, group] of this.grabs) {
      const stick = controller.userData.gamepad?.axes?.[3] || 0;  // thumbstick forward/back scales the held tree
      if (Math.abs(stick) > 0.2) group.scale.multiplyScalar(1 - 0.02 * stick);
    }
    for (const controller of this.controllers) {
      const hit = this.aim(controller);
      controller.userData.ray.scale.z = hit ? hit.distance : 5;
    }
    this.viewer.renderer.render(this.scene, this.viewer.camera);
  }

  drawPanel() {
    const g = this.panelCanvas.getContext('2d');
    g.fillStyle = '#1f252d';
    g.fillRect(0, 0, PANEL_W, PANEL_H);
    g.fillStyle = '#dde2e8';
    g.font = 'bold 40px sans-serif';
    const entry = this.selected?.userData.entry;
    g.fillText(entry ? entry.tree_id : 'point at a tree', 30, 70);
    g.font = '30px sans-serif';
    if (entry) {
      g.fillText(`${entry.species} · ${entry.height?.toFixed(1) ?? '-'} m · ${entry.mine || 'no verdict yet'}`, 30, 125);
      const flags = Object.keys(entry.flags || {});
      g.fillStyle = flags.length ? '#d2a8ff' : '#7ee787';
      g.fillText(flags.length ? `QA: ${flags.join(', ')}` : 'QA: clean', 30, 175);
    }
    g.fillStyle = '#9aa5b1';
    g.font = '24px sans-serif';
    g.fillText('trigger: pick / press · squeeze: grab and turn · both hands or stick: scale', 30, 250);
    for (const [, label, x, y, w, h, colour] of BUTTONS) {
      g.fillStyle = colour;
      g.fillRect(x, y, w, h);
      g.fillStyle = '#ffffff';
      g.font = 'bold 34px sans-serif';
      g.fillText(label, x + 16, y + h / 2 + 12);
    }
    this.panelTexture.needsUpdate = true;
  }
}
