// VR mode (WebXR immersive-vr): the session at table scale in front of the modeller. Right hand: the trigger
// draws with the current tool (stroke, branch, brush) or presses the menu; squeeze grabs the nearest branch and
// moves and turns its subtree with the hand, or, away from branches, pulls the lobe surface where the hand is. Left hand: the tool menu; its thumbstick turns the model (the seed's
// touchpad rotation, eq. 4.1). Right thumbstick: brush size (sideways) and density (up and down).
import * as THREE from 'three';
import { canvasPanel, controllerRay } from '../review/vr.js';

export const VR_SCALE = 0.08;  // a 15 m tree stands 1.2 m tall in the room
const PANEL_W = 512, PANEL_H = 640;
const MENU = ['stroke', 'lobe', 'branch', 'brush', 'move', 'grow', 'undo', 'redo', 'save', 'load', 'send', 'exit'];
const GRAB_REACH_M = 0.12;  // room metres from the hand to the nearest branch point a squeeze grabs
const STICK_DEAD = 0.5;

// Eq. 4.1 on a thumbstick: the signed angle (radians) from stick position p1 to p2 about the stick's centre.
export function stickTurn(p1, p2) {
  const n1 = Math.hypot(p1[0], p1[1]), n2 = Math.hypot(p2[0], p2[1]);
  if (n1 < STICK_DEAD || n2 < STICK_DEAD) return 0;
  const cosine = THREE.MathUtils.clamp((p1[0] * p2[0] + p1[1] * p2[1]) / (n1 * n2), -1, 1);
  const tau = Math.sign(p1[0] * p2[1] - p1[1] * p2[0]);
  return tau * Math.acos(cosine);
}

export class ModelVR {
  constructor(app) {
    this.app = app;
    this.session = null;
    this.state = 'off';
    this.hands = {};  // handedness -> controller
    this.drawing = null;  // room points of the trigger stroke in progress, in model coordinates
    this.grab = null;
    this.shaping = null;
    this.lastStick = null;
    this.raycaster = new THREE.Raycaster();
    window.modelVR = this;
  }

  async supported() {
    if (!('xr' in navigator) || !navigator.xr) return false;
    try { return await navigator.xr.isSessionSupported('immersive-vr'); } catch (_) { return false; }
  }

  async enter() {
    const session = await navigator.xr.requestSession('immersive-vr', { optionalFeatures: ['local-floor'] });
    const viewer = this.app.viewer, renderer = viewer.renderer;
    const floor = !session.enabledFeatures || session.enabledFeatures.includes('local-floor');
    renderer.xr.setReferenceSpaceType(floor ? 'local-floor' : 'local');
    renderer.xr.enabled = true;
    if (this.controllers) {  // three.js keeps its controllers between sessions: so do their listeners
      for (const controller of this.controllers) viewer.scene.add(controller);
    } else {
      this.controllers = [0, 1].map((i) => this.makeController(i));
      this.buildMenu();
    }
    session.addEventListener('end', () => this.exit());
    await renderer.xr.setSession(session);
    this.session = session;
    const root = this.app.view.root;
    root.scale.setScalar(VR_SCALE);
    root.position.set(0, 0, -0.9);
    this.app.plane.visible = false;
    viewer.ground.visible = false;
    viewer.externalLoop = (time, frame) => this.frame(time, frame);
    this.state = 'presenting';
  }

  exit() {
    if (!this.session) return;
    this.session = null;
    const viewer = this.app.viewer;
    viewer.externalLoop = this.app.desktopLoop;
    viewer.renderer.xr.enabled = false;
    for (const controller of this.controllers) viewer.scene.remove(controller);
    this.app.showPreview(null);
    const root = this.app.view.root;
    root.scale.setScalar(1);
    root.position.set(0, 0, 0);
    root.rotation.set(0, 0, 0);
    viewer.ground.visible = true;
    this.app.setTool(this.app.tool);
    this.state = 'ended';
    viewer.resize();
    this.app.redraw();
  }

  makeController(i) {
    const controller = this.app.viewer.renderer.xr.getController(i);
    const ray = controllerRay(0.3);
    controller.add(ray);
    controller.add(new THREE.Mesh(new THREE.SphereGeometry(0.01, 12, 8), new THREE.MeshBasicMaterial({ color: 0xffd33d })));
    controller.userData.ray = ray;
    controller.addEventListener('connected', (event) => {
      controller.userData.gamepad = event.data.gamepad;
      controller.userData.hand = event.data.handedness;
      this.hands[event.data.handedness] = controller;
      if (event.data.handedness === 'left') controller.add(this.menu);
    });
    controller.addEventListener('disconnected', () => { controller.userData.gamepad = null; });
    controller.addEventListener('selectstart', () => this.triggerStart(controller));
    controller.addEventListener('selectend', () => this.triggerEnd(controller));
    controller.addEventListener('squeezestart', () => this.squeezeStart(controller));
    controller.addEventListener('squeezeend', () => this.squeezeEnd(controller));
    this.app.viewer.scene.add(controller);
    return controller;
  }

  buildMenu() {
    ({ canvas: this.menuCanvas, texture: this.menuTexture, mesh: this.menu } = canvasPanel(PANEL_W, PANEL_H, 0.16));
    this.menu.position.set(0, 0.06, -0.08);
    this.menu.rotation.x = -0.9;
    this.refresh();
  }

  // Menu buttons in canvas pixels: two columns of six below a status line.
  buttonAt(index) {
    return [16 + (index % 2) * 248, 116 + Math.floor(index / 2) * 86, 232, 74];
  }

  refresh() {
    if (!this.menuCanvas) return;
    const g = this.menuCanvas.getContext('2d'), app = this.app;
    g.fillStyle = '#1f252d';
    g.fillRect(0, 0, PANEL_W, PANEL_H);
    g.fillStyle = '#7ee787';
    g.font = 'bold 34px sans-serif';
    g.fillText(`version ${app.version}`, 16, 46);
    g.fillStyle = app.lastError ? '#ffa198' : '#9aa5b1';
    g.font = '22px sans-serif';
    g.fillText((app.lastError || `brush ${app.$('brush-radius').value} m · ${app.$('brush-density').value}/m³`).slice(0, 40), 16, 90);
    MENU.forEach((name, i) => {
      const [x, y, w, h] = this.buttonAt(i);
      g.fillStyle = name === app.tool ? '#1f6feb' : '#39424e';
      g.fillRect(x, y, w, h);
      g.fillStyle = '#ffffff';
      g.font = 'bold 34px sans-serif';
      g.fillText(name, x + 20, y + 50);
    });
    this.menuTexture.needsUpdate = true;
  }

  press(name) {
    const app = this.app;
    if (['stroke', 'branch', 'brush', 'move'].includes(name)) app.setTool(name);
    else if (name === 'lobe') app.makeLobe();
    else if (name === 'grow') app.grow();
    else if (name === 'undo' || name === 'redo') app.edit(name);
    else if (name === 'save') app.save();
    else if (name === 'load') app.load({ name: app.$('session-name').value });
    else if (name === 'send') app.sendToLibrary();
    else if (name === 'exit') this.session.end();
    this.refresh();
  }

  tip(controller) {
    controller.updateMatrixWorld(true);
    return new THREE.Vector3().setFromMatrixPosition(controller.matrixWorld);
  }

  // A room point in the session's frame (Y up, metres): under the model root's scale and turn.
  toModel(point) {
    this.app.view.root.updateMatrixWorld(true);
    return this.app.view.root.worldToLocal(point.clone());
  }

  menuHit(controller) {
    if (!this.menu.parent) return null;
    const rotation = new THREE.Matrix4().extractRotation(controller.matrixWorld);
    this.raycaster.ray.origin.setFromMatrixPosition(controller.matrixWorld);
    this.raycaster.ray.direction.set(0, 0, -1).applyMatrix4(rotation);
    this.menu.updateMatrixWorld(true);
    const hit = this.raycaster.intersectObject(this.menu, false)[0];
    if (!hit) return null;
    const x = hit.uv.x * PANEL_W, y = (1 - hit.uv.y) * PANEL_H;
    return MENU.find((_, i) => { const [bx, by, bw, bh] = this.buttonAt(i); return x >= bx && x <= bx + bw && y >= by && y <= by + bh; }) || null;
  }

  triggerStart(controller) {
    if (controller.userData.hand === 'left') return;
    controller.updateMatrixWorld(true);
    const button = this.menuHit(controller);
    if (button) { this.press(button); return; }
    if (['stroke', 'branch', 'brush'].includes(this.app.tool)) this.drawing = { controller, points: [this.toModel(this.tip(controller))] };
  }

  triggerEnd(controller) {
    if (!this.drawing || this.drawing.controller !== controller) return;
    const points = this.drawing.points.map((p) => p.toArray());
    this.drawing = null;
    this.app.showPreview(null);
    return this.app.commitStroke(this.app.tool, points);
  }

  // Squeeze: grab the branch nearest the hand (its subtree moves with it), or else the lobe surface there.
  squeezeStart(controller) {
    const state = this.app.state;
    if (!state) return;
    const hand = this.toModel(this.tip(controller)), reach = GRAB_REACH_M / this.app.view.root.scale.x;
    let best = null;
    state.branches.forEach((branch, i) => branch.points.forEach((p) => {
      const d = hand.distanceTo(new THREE.Vector3(...p));
      if (!best || d < best.distance) best = { branch: i, distance: d };
    }));
    if (!best || best.distance > reach) {
      const surface = this.app.view.nearestLobePoint(state, hand);
      if (surface && surface.distance <= reach) this.shaping = { controller, ...surface };
      return;
    }  // room metres
    this.app.view.select(best.branch);
    controller.updateMatrixWorld(true);
    this.grab = { controller, branch: best.branch, start: hand, startTurn: this.modelTurn(controller),
                  base: new THREE.Vector3(...state.branches[best.branch].points[0]),
                  members: this.app.view.subtree(state, best.branch) };
  }

  // The controller's orientation in the session's frame.
  modelTurn(controller) {
    const world = new THREE.Quaternion().setFromRotationMatrix(new THREE.Matrix4().extractRotation(controller.matrixWorld));
    const root = this.app.view.root.getWorldQuaternion(new THREE.Quaternion());
    return root.invert().multiply(world);
  }

  // The grab's rigid motion so far: rotation R (Matrix4) and translation t about the branch base b,
  // p' = R (p - b) + b + t, from the hand's turn and its path (both in the session's frame).
  grabMotion() {
    const grab = this.grab, controller = grab.controller;
    const turn = this.modelTurn(controller).multiply(grab.startTurn.clone().invert());
    const rotation = new THREE.Matrix4().makeRotationFromQuaternion(turn);
    const hand = this.toModel(this.tip(controller));
    const translation = grab.base.clone().sub(grab.start).applyMatrix4(rotation).add(hand).sub(grab.base);
    return { rotation, translation };
  }

  async squeezeEnd(controller) {
    if (this.shaping && this.shaping.controller === controller) {
      const { lobe, handle } = this.shaping;
      this.shaping = null;
      await this.app.edit('drag-surface', { lobe, handle, target: this.toModel(this.tip(controller)).toArray(),
                                            radius: this.app.view.dragRadius(this.app.state, lobe) });
      return;
    }
    if (!this.grab || this.grab.controller !== controller) return;
    const { rotation, translation } = this.grabMotion();
    const branch = this.grab.branch;
    this.grab = null;
    const e = rotation.elements;
    const rows = [0, 1, 2].map((i) => [0, 1, 2].map((j) => e[4 * j + i]));
    const state = await this.app.edit('move', { branch, rotation: rows, translation: translation.toArray() });
    if (!state) this.app.view.show(this.app.state);
  }

  // The brush's sphere round the right hand while the brush tool is chosen, at its size in the room.
  showBrush() {
    const hand = this.hands.right;
    if (!hand) return;
    if (!this.brushSphere) {
      this.brushSphere = new THREE.Mesh(new THREE.SphereGeometry(1, 16, 12),
                                        new THREE.MeshBasicMaterial({ color: 0xff7b72, wireframe: true, transparent: true, opacity: 0.4 }));
      hand.add(this.brushSphere);
    }
    this.brushSphere.visible = this.app.tool === 'brush';
    this.brushSphere.scale.setScalar(Number(this.app.$('brush-radius').value) * this.app.view.root.scale.x);
  }

  sticks() {
    const left = this.hands.left?.userData.gamepad, right = this.hands.right?.userData.gamepad;
    const axes = (pad) => (pad && pad.axes.length >= 4 ? [pad.axes[2], pad.axes[3]] : pad ? [pad.axes[0] || 0, pad.axes[1] || 0] : [0, 0]);
    const turnStick = axes(left);
    if (this.lastStick) this.app.view.root.rotation.y -= stickTurn(this.lastStick, turnStick);
    this.lastStick = turnStick;
    const [x, y] = axes(right);
    if (Math.abs(x) > 0.2 || Math.abs(y) > 0.2) {
      const radius = this.app.$('brush-radius'), density = this.app.$('brush-density');
      radius.value = THREE.MathUtils.clamp(Number(radius.value) * (1 + 0.02 * x), 0.2, 4).toFixed(2);
      density.value = THREE.MathUtils.clamp(Number(density.value) * (1 - 0.02 * y), 1, 60).toFixed(1);
      this.refresh();
    }
  }

  frame() {
    const viewer = this.app.viewer;
    if (this.drawing) {
      const point = this.toModel(this.tip(this.drawing.controller));
      if (point.distanceTo(this.drawing.points[this.drawing.points.length - 1]) >= 0.05) {
        this.drawing.points.push(point);
        this.app.showPreview(this.drawing.points);
      }
    }
    this.showBrush();
    if (this.grab) {
      const { rotation, translation } = this.grabMotion(), b = this.grab.base;
      const matrix = new THREE.Matrix4().makeTranslation(b.x + translation.x, b.y + translation.y, b.z + translation.z)
        .multiply(rotation).multiply(new THREE.Matrix4().makeTranslation(-b.x, -b.y, -b.z));
      for (const i of this.grab.members) {
        const mesh = this.app.view.branchMeshes[i];
        mesh.matrixAutoUpdate = false;
        mesh.matrix.copy(matrix);
      }
    }
    this.sticks();
    viewer.renderer.render(viewer.scene, viewer.camera);
  }
}
