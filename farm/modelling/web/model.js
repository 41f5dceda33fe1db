// The modelling page, desktop mode: an orbit camera over the session, strokes drawn with the mouse on a vertical
// plane the user turns and pushes, tool buttons, and the tree the server grows after every edit. VR mode (vr.js)
// edits the same session through the same calls.
import * as THREE from 'three';
import * as api from './api.js';
import { TreeViewer } from '../review/viewer.js';
import { SessionView } from './session_view.js';
import { ModelVR } from './vr.js';

const DRAWING = new Set(['stroke', 'branch', 'brush']);
const MIN_STEP_M = 0.05;  // pointer samples closer than this to the last one are skipped (the server resamples)

export class ModelApp {
  constructor() {
    this.viewer = new TreeViewer(document.getElementById('viewer'));
    this.viewer.camera.position.set(18, 10, 24);
    this.viewer.controls.target.set(0, 7, 0);
    this.viewer.camera.near = 0.1;
    this.viewer.camera.far = 400;
    this.viewer.camera.updateProjectionMatrix();
    this.viewer.ground.scale.setScalar(14);
    this.view = new SessionView();
    this.viewer.scene.add(this.view.root);
    this.plane = new THREE.Mesh(new THREE.PlaneGeometry(30, 34),
                                new THREE.MeshBasicMaterial({ color: 0x58a6ff, transparent: true, opacity: 0.08,
                                                              side: THREE.DoubleSide, depthWrite: false }));
    this.plane.add(new THREE.LineSegments(new THREE.EdgesGeometry(this.plane.geometry),
                                          new THREE.LineBasicMaterial({ color: 0x58a6ff })));
    this.viewer.scene.add(this.plane);
    this.planeTurn = 0;
    this.planeDepth = 0;
    this.placePlane();
    this.raycaster = new THREE.Raycaster();
    this.tool = 'view';
    this.state = null;
    this.version = -1;
    this.stroke = null;  // points of the stroke being drawn (Y up)
    this.dragging = null;  // the move tool's drag
    this.preview = null;
    this.lastError = null;
    // Desktop frames are drawn when something changed (an edit, a tree, the camera, the pointer), not sixty times
    // a second: the page stays responsive on a slow GPU or a software renderer while the server grows.
    this.dirty = true;
    this.drawnVersion = -1;  // the session version whose tree the last drawn frame showed
    this.viewer.controls.addEventListener('change', () => this.redraw());
    new ResizeObserver(() => this.redraw()).observe(this.viewer.container);
    this.desktopLoop = () => this.desktopFrame();
    this.viewer.externalLoop = this.desktopLoop;
    this.vr = new ModelVR(this);
    window.modelApp = this;
    this.bind();
    this.setTool('stroke');
  }

  $(id) { return document.getElementById(id); }

  redraw() { this.dirty = true; }

  desktopFrame() {
    const moved = this.viewer.controls.update();  // true while the camera moves (damping included)
    if (!moved && !this.dirty) return;
    this.dirty = false;
    this.viewer.renderer.render(this.viewer.scene, this.viewer.camera);
    if (this.view.treeVersion > this.drawnVersion) this.drawnVersion = this.view.treeVersion;
  }

  setStatus(message, error = false) {
    const status = this.$('status');
    status.textContent = message;
    status.classList.toggle('error', error);
    if (error) this.lastError = message;
  }

  // Run an API call; its error goes to the status line (the session is as it was: the server refused it).
  async call(action, done) {
    try {
      const result = await action();
      this.lastError = null;
      if (done) this.setStatus(done(result));
      return result;
    } catch (error) {
      this.setStatus(error.message, true);
      return null;
    }
  }

  async start() {
    const state = await this.call(api.state);
    if (state) this.apply(state);
    if (await this.vr.supported()) {
      const button = this.$('enter-vr');
      button.disabled = false;
      button.textContent = 'Enter VR';
      button.onclick = () => this.call(() => this.vr.enter());
    }
    // Another page or a headset may edit the session too: the later edit wins, so follow the version.
    setInterval(async () => {
      try {
        const state = await api.state();
        if (state.version > this.version) this.apply(state);
      } catch (_) { /* the next poll tries again */ }
    }, 1500);
  }

  // A new session state from the server: draw it, show its version, grow its tree.
  apply(state) {
    if (state.version < this.version) return;
    this.state = state;
    this.version = state.version;
    this.view.show(state);
    this.redraw();
    this.$('version').textContent = `version ${state.version}`;
    this.$('undo').disabled = !state.can_undo;
    this.$('redo').disabled = !state.can_redo;
    const preset = this.$('preset');
    if (preset.options.length !== state.presets.length) {
      preset.replaceChildren(...state.presets.map((name) => new Option(name, name)));
    }
    preset.value = state.preset;
    this.$('seed').value = state.seed;
    this.$('counts').textContent = `${state.strokes.length} strokes · ${state.lobes.length} lobes · `
      + `${state.branches.length} branches · ${state.marker_count} markers`;
    this.vr.refresh();
    // Live growth needs somewhere to grow: a lobe or painted markers.
    if (this.$('auto-grow').checked && (state.lobes.length || state.marker_count)) this.grow();
  }

  async edit(tool, body = {}) {
    const state = await this.call(() => api.post(tool, body), () => `${tool}: done`);
    if (state) this.apply(state);
    return state;
  }

  // Grow the current version; a reply for a version a newer edit overtook is null (dropped by the server).
  async grow() {
    const version = this.version;
    const grown = await this.call(() => api.grow(version));
    if (!grown) return false;
    if (await this.view.showTree(grown.glb, grown.version)) {
      this.redraw();
      if (!this.$('status').classList.contains('error')) this.setStatus(`tree of version ${grown.version}`);
    }
    return true;
  }

  setTool(tool) {
    this.tool = tool;
    for (const button of document.querySelectorAll('[data-tool]')) button.classList.toggle('active', button.dataset.tool === tool);
    const orbit = tool === 'view';
    this.viewer.controls.mouseButtons = { LEFT: orbit ? THREE.MOUSE.ROTATE : -1, MIDDLE: THREE.MOUSE.DOLLY,
                                          RIGHT: orbit ? THREE.MOUSE.PAN : THREE.MOUSE.ROTATE };
    this.plane.visible = DRAWING.has(tool) || tool === 'move';
    if (this.handle) this.handle.visible = false;
    this.vr.refresh();
  }

  placePlane() {
    const angle = THREE.MathUtils.degToRad(this.planeTurn);
    const normal = new THREE.Vector3(Math.sin(angle), 0, Math.cos(angle));
    this.plane.position.copy(normal.clone().multiplyScalar(this.planeDepth)).add(new THREE.Vector3(0, 15, 0));  // from 2 m below the ground to 32 m up
    this.plane.rotation.set(0, angle, 0);
    this.plane.updateMatrixWorld(true);
    this.$('plane-turn-value').textContent = `${Math.round(this.planeTurn)}°`;
  }

  turnPlane(degrees) {
    this.planeTurn = ((this.planeTurn + degrees + 540) % 360) - 180;
    this.$('plane-turn').value = this.planeTurn;
    this.placePlane();
  }

  pointer(event) {
    const rect = this.viewer.renderer.domElement.getBoundingClientRect();
    const ndc = new THREE.Vector2(((event.clientX - rect.left) / rect.width) * 2 - 1,
                                  -((event.clientY - rect.top) / rect.height) * 2 + 1);
    this.raycaster.setFromCamera(ndc, this.viewer.camera);
    return this.raycaster;
  }

  planePoint(event) {
    const hit = this.pointer(event).intersectObject(this.plane, false)[0];
    return hit ? hit.point : null;
  }

  down(event) {
    if (event.button !== 0) return;
    if (DRAWING.has(this.tool)) {
      const point = this.planePoint(event);
      if (!point) return;
      this.stroke = [point];
      this.showPreview();
    } else if (this.tool === 'shape') {
      this.startShape(event);
    } else if (this.tool === 'move') {
      const hit = this.pointer(event).intersectObjects(this.view.branchMeshes, false)[0];
      const point = this.planePoint(event);
      if (!hit || !point) return;
      const branch = hit.object.userData.branch;
      this.view.select(branch);
      const base = new THREE.Vector3(...this.state.branches[branch].points[0]);
      this.dragging = { branch, start: point, x: event.clientX, base, members: this.view.subtree(this.state, branch),
                        matrix: new THREE.Matrix4(), translation: new THREE.Vector3(), rotation: new THREE.Matrix4() };
    }
  }

  move(event) {
    if (this.stroke) {
      const point = this.planePoint(event);
      if (point && point.distanceTo(this.stroke[this.stroke.length - 1]) >= MIN_STEP_M) {
        this.stroke.push(point);
        this.showPreview();
      }
    } else if (this.shaping) {
      const target = this.pointer(event).ray.intersectPlane(this.shaping.plane, new THREE.Vector3());
      if (target) { this.shaping.target = target; this.handle.position.copy(target); }
    } else if (this.dragging) {
      const drag = this.dragging, point = this.planePoint(event);
      if (event.shiftKey) {
        const axis = new THREE.Vector3(0, 0, 1).applyQuaternion(this.plane.quaternion);
        drag.rotation.makeRotationAxis(axis, (event.clientX - drag.x) * 0.01);
      } else if (point) drag.translation.copy(point).sub(drag.start);
      // about the branch base: T(base + t) R T(-base)
      drag.matrix.makeTranslation(drag.base.x + drag.translation.x, drag.base.y + drag.translation.y, drag.base.z + drag.translation.z)
        .multiply(drag.rotation).multiply(new THREE.Matrix4().makeTranslation(-drag.base.x, -drag.base.y, -drag.base.z));
      for (const i of drag.members) {
        const mesh = this.view.branchMeshes[i];
        mesh.matrixAutoUpdate = false;
        mesh.matrix.copy(drag.matrix);
      }
    }
  }

  // Shape tool: press on a lobe and drag its surface (Laplacian edit), or with shift a point of one of its strokes
  // (a quadratic Bezier span); the point moves on a plane facing the camera.
  startShape(event) {
    const ray = this.pointer(event);
    let grabbed = null;
    if (event.shiftKey) {  // the lobe stroke point nearest the pointer's ray, within half a metre of it
      let best = null;
      this.state.lobes.forEach((lobe, i) => lobe.strokes.forEach((stroke, k) => stroke.forEach((p, j) => {
        const d = ray.ray.distanceSqToPoint(new THREE.Vector3(...p));
        if (!best || d < best.d) best = { d, kind: 'stroke', lobe: i, stroke: k, index: j, point: p };
      })));
      if (best && best.d < 0.25) grabbed = best;
    } else {
      const hit = ray.intersectObjects(this.view.lobeMeshes, false)[0];
      if (hit) {
        const lobe = hit.object.userData.lobe, vertices = this.state.lobes[lobe].vertices;
        const handle = [hit.face.a, hit.face.b, hit.face.c].reduce((a, b) =>
          hit.point.distanceTo(new THREE.Vector3(...vertices[a])) <= hit.point.distanceTo(new THREE.Vector3(...vertices[b])) ? a : b);
        grabbed = { kind: 'surface', lobe, handle, point: vertices[handle] };
      }
    }
    if (!grabbed) return;
    const start = new THREE.Vector3(...grabbed.point);
    const facing = this.viewer.camera.getWorldDirection(new THREE.Vector3());
    if (!this.handle) {
      this.handle = new THREE.Mesh(new THREE.SphereGeometry(0.15, 12, 8), new THREE.MeshBasicMaterial({ color: 0xff7b72 }));
      this.viewer.scene.add(this.handle);
    }
    this.handle.visible = true;
    this.handle.position.copy(start);
    this.shaping = { ...grabbed, target: start, plane: new THREE.Plane().setFromNormalAndCoplanarPoint(facing, start) };
  }

  async up() {
    if (this.shaping) {
      const shape = this.shaping, target = shape.target.toArray();
      this.shaping = null;
      this.handle.visible = false;
      if (shape.kind === 'surface') {
        await this.edit('drag-surface', { lobe: shape.lobe, handle: shape.handle, target,
                                          radius: this.view.dragRadius(this.state, shape.lobe) });
      } else await this.edit('drag-stroke', { lobe: shape.lobe, stroke: shape.stroke, index: shape.index, target });
    } else if (this.stroke) {
      const points = this.stroke.map((p) => p.toArray());
      this.stroke = null;
      this.showPreview();
      await this.commitStroke(this.tool, points);
    } else if (this.dragging) {
      const drag = this.dragging;
      this.dragging = null;
      const e = drag.rotation.elements;  // column-major: row i, column j is e[4 j + i]
      const rotation = [0, 1, 2].map((i) => [0, 1, 2].map((j) => e[4 * j + i]));
      const state = await this.edit('move', { branch: drag.branch, rotation, translation: drag.translation.toArray() });
      if (!state) this.view.show(this.state);  // refused: the branches go back where the session has them
    }
  }

  // A finished stroke of a drawing tool (points Y up, the session's frame): one API call.
  commitStroke(tool, points) {
    if (tool === 'stroke') return this.edit('stroke', { points });
    if (tool === 'branch') return this.edit('branch', { points });
    return this.edit('brush', { path: points, radius: Number(this.$('brush-radius').value),
                                density: Number(this.$('brush-density').value) });
  }

  // The stroke being drawn (points in the session's frame, Y up; none: remove it), in white under the model
  // root, so VR mode's scaled room shows it too.
  showPreview(points = this.stroke) {
    const root = this.view.root;
    if (this.preview) { root.remove(this.preview); this.preview.geometry.dispose(); this.preview = null; }
    if (!points || points.length < 2) return;
    this.preview = new THREE.Line(new THREE.BufferGeometry().setFromPoints(points),
                                  new THREE.LineBasicMaterial({ color: 0xffffff }));
    root.add(this.preview);
  }

  // Make a lobe of the drawn strokes, or, when they lie inside an existing lobe's box (and `fresh` is not asked),
  // add them to that lobe: only the strips next to them are rebuilt.
  makeLobe(fresh = false) {
    const points = (this.state?.strokes || []).flat().map((p) => new THREE.Vector3(...p));
    const centre = points.reduce((sum, p) => sum.add(p), new THREE.Vector3()).divideScalar(Math.max(points.length, 1));
    const lobe = fresh || !points.length ? -1 : this.state.lobes.findIndex((l) =>
      new THREE.Box3().setFromPoints(l.vertices.map((p) => new THREE.Vector3(...p))).containsPoint(centre));
    return this.edit('lobe', lobe >= 0 ? { lobe } : {});
  }

  async save() {
    const name = this.$('session-name').value;
    return this.call(() => api.post('save', { name }), (r) => `saved ${r.path} (${r.bytes} bytes)`);
  }

  async load(body) {
    const state = await this.call(() => api.post('load', body), (s) => `loaded: version ${s.version}`);
    if (state) this.apply(state);
    return state;
  }

  async sendToLibrary() {
    this.setStatus('building the library asset…');
    return this.call(() => api.post('send-to-library'), (r) => `sent to the library as ${r.id}`);
  }

  bind() {
    const canvas = this.viewer.renderer.domElement;
    for (const type of ['pointerdown', 'pointermove', 'pointerup', 'wheel', 'keydown', 'input', 'click']) {
      window.addEventListener(type, () => this.redraw(), { capture: true, passive: true });
    }
    canvas.addEventListener('pointerdown', (e) => this.down(e));
    canvas.addEventListener('pointermove', (e) => this.move(e));
    window.addEventListener('pointerup', () => this.up());
    for (const button of document.querySelectorAll('[data-tool]')) button.onclick = () => this.setTool(button.dataset.tool);
    this.$('make-lobe').onclick = (e) => this.makeLobe(e.shiftKey);
    this.$('grow').onclick = () => this.grow();
    this.$('undo').onclick = () => this.edit('undo');
    this.$('redo').onclick = () => this.edit('redo');
    this.$('save').onclick = () => this.save();
    this.$('load').onclick = () => this.load({ name: this.$('session-name').value });
    this.$('send').onclick = () => this.sendToLibrary();
    this.$('download').href = api.sessionURL();
    this.$('load-file').onchange = async (e) => { if (e.target.files[0]) await this.load(await e.target.files[0].text()); };
    this.$('preset').onchange = (e) => this.edit('growth', { preset: e.target.value });
    this.$('seed').onchange = (e) => this.edit('growth', { seed: Number(e.target.value) });
    this.$('plane-turn').oninput = (e) => { this.planeTurn = Number(e.target.value); this.placePlane(); };
    this.$('plane-depth').oninput = (e) => { this.planeDepth = Number(e.target.value); this.placePlane(); };
    const keys = { v: 'view', s: 'stroke', b: 'branch', p: 'brush', m: 'move', h: 'shape' };
    window.addEventListener('keydown', (e) => {
      if (e.target.tagName === 'INPUT' || e.target.tagName === 'SELECT') return;
      if (e.ctrlKey && e.key === 'z') this.edit('undo');
      else if (e.ctrlKey && e.key === 'y') this.edit('redo');
      else if (keys[e.key]) this.setTool(keys[e.key]);
      else if (e.key === 'l' || e.key === 'L') this.makeLobe(e.shiftKey);
      else if (e.key === 'g') this.grow();
      else if (e.key === 'q' || e.key === 'e') this.turnPlane(e.key === 'q' ? -15 : 15);
    });
  }
}

new ModelApp().start();
