// The session drawn in three.js (Y up, metres): drawn strokes, lobes (see-through), main branches as tubes,
// painted markers as points, and the grown tree. One group, `root`, which VR mode scales into the room.
import * as THREE from 'three';
import { disposeObject, parseGLB } from '../review/viewer.js';

const STROKE = new THREE.LineBasicMaterial({ color: 0xffd33d });
const LOBE_STROKE = new THREE.LineBasicMaterial({ color: 0x9be9a8 });
const LOBE = new THREE.MeshLambertMaterial({ color: 0x3fb950, transparent: true, opacity: 0.25, depthWrite: false,
                                             side: THREE.DoubleSide });
const BRANCH = new THREE.MeshLambertMaterial({ color: 0x8b5a2b });
const SELECTED = new THREE.MeshLambertMaterial({ color: 0x58a6ff });
const MARKER = new THREE.PointsMaterial({ color: 0xff7b72, size: 4, sizeAttenuation: false });

function line(points, material) {
  const geometry = new THREE.BufferGeometry().setFromPoints(points.map((p) => new THREE.Vector3(...p)));
  return new THREE.Line(geometry, material);
}

export function branchTube(points, radius = 0.08) {
  const curve = new THREE.CatmullRomCurve3(points.map((p) => new THREE.Vector3(...p)));
  return new THREE.Mesh(new THREE.TubeGeometry(curve, Math.max(points.length * 2, 8), radius, 6), BRANCH);
}

export class SessionView {
  constructor() {
    this.root = new THREE.Group();
    this.drawn = new THREE.Group();  // strokes, lobes, branches, markers: rebuilt from each state
    this.root.add(this.drawn);
    this.tree = null;
    this.treeVersion = -1;
    this.branchMeshes = [];
    this.lobeMeshes = [];
    this.selected = -1;
  }

  show(state) {
    for (const child of [...this.drawn.children]) { this.drawn.remove(child); disposeObject(child); }
    for (const stroke of state.strokes) this.drawn.add(line(stroke, STROKE));
    this.lobeMeshes = state.lobes.map((lobe, i) => {
      const geometry = new THREE.BufferGeometry();
      geometry.setAttribute('position', new THREE.Float32BufferAttribute(lobe.vertices.flat(), 3));
      geometry.setIndex(lobe.faces.flat());
      geometry.computeVertexNormals();
      const mesh = new THREE.Mesh(geometry, LOBE);
      mesh.userData.lobe = i;
      this.drawn.add(mesh);
      for (const stroke of lobe.strokes) this.drawn.add(line(stroke, LOBE_STROKE));
      return mesh;
    });
    this.branchMeshes = state.branches.map((branch, i) => {
      const tube = branchTube(branch.points);
      tube.userData.branch = i;
      this.drawn.add(tube);
      return tube;
    });
    if (state.markers.length) {
      const geometry = new THREE.BufferGeometry();
      geometry.setAttribute('position', new THREE.Float32BufferAttribute(state.markers.flat(), 3));
      this.drawn.add(new THREE.Points(geometry, MARKER));
    }
    this.select(this.selected < this.branchMeshes.length ? this.selected : -1);
  }

  select(index) {
    this.selected = index;
    this.branchMeshes.forEach((mesh, i) => { mesh.material = i === index ? SELECTED : BRANCH; });
  }

  // The branches of a subtree (the branch and every one growing from it), from the state's parent indices.
  subtree(state, index) {
    const members = new Set([index]);
    let grown = true;
    while (grown) {
      grown = false;
      state.branches.forEach((b, i) => { if (members.has(b.parent) && !members.has(i)) { members.add(i); grown = true; } });
    }
    return [...members];
  }

  // The lobe vertex or lobe stroke point nearest `point` (Y up): {kind: 'surface' | 'stroke', lobe, handle |
  // (stroke, index), distance}, or null without lobes.
  nearestLobePoint(state, point, strokes = false) {
    let best = null;
    const consider = (p, found) => {
      const d = point.distanceTo(new THREE.Vector3(...p));
      if (!best || d < best.distance) best = { ...found, distance: d };
    };
    state.lobes.forEach((lobe, i) => {
      if (strokes) lobe.strokes.forEach((stroke, k) => stroke.forEach((p, j) => consider(p, { kind: 'stroke', lobe: i, stroke: k, index: j })));
      else lobe.vertices.forEach((p, j) => consider(p, { kind: 'surface', lobe: i, handle: j }));
    });
    return best;
  }

  // The reach of a surface drag: 0.3 of the lobe's widest extent (vertices farther stay where they are).
  dragRadius(state, lobe) {
    const box = new THREE.Box3().setFromPoints(state.lobes[lobe].vertices.map((p) => new THREE.Vector3(...p)));
    const size = box.getSize(new THREE.Vector3());
    return 0.3 * Math.max(size.x, size.y, size.z);
  }

  // Show a grown tree (GLB bytes of `version`); an older version arriving late is not shown.
  async showTree(buffer, version) {
    if (version < this.treeVersion) return false;
    const gltf = await parseGLB(buffer);
    if (version < this.treeVersion) { disposeObject(gltf.scene); return false; }
    if (this.tree) { this.root.remove(this.tree); disposeObject(this.tree); }
    this.tree = gltf.scene;
    this.treeVersion = version;
    this.root.add(this.tree);
    return true;
  }
}
