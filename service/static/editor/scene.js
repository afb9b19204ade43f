// The three.js scene: renderer, camera, orbit controls, and the drawing of the skeleton
// (joints, bones, pin rings), of an open file's own bones, and of the targets.

import * as THREE from 'three';
import { OrbitControls } from 'three/addons/controls/OrbitControls.js';
import { $, doc, state, ui } from './state.js';
import { ApiError, showError } from './api.js';
import { rowFrame, toWorld } from './file.js';
import { fileRow } from './rows.js';

const COLORS = {
  left: 0x3b82f6,
  right: 0xf59e0b,
  centre: 0xc3c8d2,
  pin: 0xa855f7,
  target: 0xef4444,
  hover: 0xffffff,
  selected: 0xfacc15,
};
const JOINT_RADIUS = 0.026;
const BONE_RADIUS = 0.016;
const HEAD_RADIUS = 0.075;
export const TARGET_RADIUS = 0.036;

// The radius (m) of a joint's handle as drawn: a sample's head is a larger sphere.
export const handleRadius = (name) => (name === 'head' && !doc.active ? HEAD_RADIUS : JOINT_RADIUS);

// ------------------------------------------------------------------------------------
// Scene
// ------------------------------------------------------------------------------------
export const viewport = $('viewport');
export let renderer;
try {
  renderer = new THREE.WebGLRenderer({ antialias: true, preserveDrawingBuffer: true });
} catch (err) {
  showError(new ApiError(-1, 'WebGL unavailable', `the 3D view cannot start: ${err.message}`));
  throw err;
}
renderer.setPixelRatio(Math.min(window.devicePixelRatio, 2));
viewport.appendChild(renderer.domElement);

export const scene = new THREE.Scene();
scene.background = new THREE.Color(0x1c2028);
export const camera = new THREE.PerspectiveCamera(38, 1, 0.05, 100);
camera.position.set(0.75, 1.3, 2.9);

scene.add(new THREE.HemisphereLight(0xffffff, 0x404552, 2.2));
const sun = new THREE.DirectionalLight(0xffffff, 2.0);
sun.position.set(2, 4, 3);
scene.add(sun);

// Floor: a 4 m grid of 25 cm squares.
const floor = new THREE.GridHelper(4, 16, 0x6b7280, 0x394050);
scene.add(floor);

// Facing arrow on the floor (+Z, towards the default camera).
const facing = new THREE.ArrowHelper(new THREE.Vector3(0, 0, 1), new THREE.Vector3(0, 0.003, 0.15), 0.25, 0x6b7280, 0.07, 0.045);
scene.add(facing);

// The floor (and the facing arrow) under the point (x, z), snapped to its 0.25 m cells so
// that its lines stay where they were: a file's character followed from frame to frame
// (file.js followFrame) walked off the 4 m grid and stood on nothing.
export function centreFloor(x, z) {
  const cell = 0.25;
  floor.position.set(Math.round(x / cell) * cell, 0, Math.round(z / cell) * cell);
  facing.position.set(floor.position.x, 0.003, floor.position.z + 0.15);
  ui.needsRender = true;
}

export const floorCentre = () => floor.position.toArray();

export const controls = new OrbitControls(camera, renderer.domElement);
controls.target.set(0, 0.85, 0);
controls.enableDamping = false;
controls.update();

const side = (name) => (name.startsWith('left_') ? 'left' : name.startsWith('right_') ? 'right' : 'centre');
const materials = {
  left: new THREE.MeshStandardMaterial({ color: COLORS.left, roughness: 0.5 }),
  right: new THREE.MeshStandardMaterial({ color: COLORS.right, roughness: 0.5 }),
  centre: new THREE.MeshStandardMaterial({ color: COLORS.centre, roughness: 0.5 }),
  pin: new THREE.MeshStandardMaterial({ color: COLORS.pin, roughness: 0.4, emissive: 0x3b0764 }),
  // A target marker is drawn twice (``targetMarker``): where the body hides it, a faint flat
  // red (``targetHidden``, over the body), and where it is seen, lit and solid (``target``,
  // depth-tested). Drawn over the body alone, as it was, a marker behind the body looked
  // the same as one in front: orbiting, the user could not tell which side it was on.
  target: new THREE.MeshStandardMaterial({
    color: COLORS.target, roughness: 0.4, emissive: 0x450a0a, transparent: true, opacity: 0.9, depthWrite: false,
  }),
  targetHidden: new THREE.MeshBasicMaterial({
    color: COLORS.target, transparent: true, opacity: 0.3, depthTest: false, depthWrite: false,
  }),
  // A marker inside its own joint's handle (a target at a sample's head, whose 0.075 m sphere
  // holds the 0.036 m marker) is at its joint, not behind the body: drawn solid over it (in
  // the handle, it was neither seen nor found to be grabbed)
  targetOver: new THREE.MeshStandardMaterial({
    color: COLORS.target, roughness: 0.4, emissive: 0x450a0a, transparent: true, opacity: 0.85, depthTest: false, depthWrite: false,
  }),
  hover: new THREE.MeshStandardMaterial({ color: COLORS.hover, roughness: 0.3, emissive: 0x555555 }),
};
const sphereGeometry = new THREE.SphereGeometry(1, 24, 16);
const boneGeometry = new THREE.CylinderGeometry(BONE_RADIUS, BONE_RADIUS, 1, 16, 1);
const pinRingGeometry = new THREE.TorusGeometry(0.045, 0.007, 8, 32);
// The joint selected for the keys and the panel (keys.js): a yellow ring, wider than a pin's
// and than the joint's handle (a sample's head), facing the camera (the frame loop turns it
// with the pin rings), drawn over the body (a joint behind it still shows its ring).
const SELECTION_RADIUS = 0.068;
export const selectionRing = new THREE.Mesh(
  new THREE.TorusGeometry(SELECTION_RADIUS, 0.006, 8, 40),
  new THREE.MeshBasicMaterial({ color: COLORS.selected, depthTest: false, transparent: true }),
);
selectionRing.renderOrder = 10;
selectionRing.visible = false;
scene.add(selectionRing);

const skeleton = new THREE.Group();
scene.add(skeleton);
const jointMeshes = new Map();
const boneMeshes = new Map(); // child -> mesh
export const pinRings = new Map();
const targetMarkers = new Map();
const targetLines = new Map();

export function buildSkeleton() {
  skeleton.clear();
  jointMeshes.clear();
  boneMeshes.clear();
  pinRings.clear();
  for (const name of state.joints) {
    const mesh = new THREE.Mesh(sphereGeometry, materials[side(name)]);
    mesh.scale.setScalar(handleRadius(name));
    mesh.name = name;
    skeleton.add(mesh);
    jointMeshes.set(name, mesh);
    const parent = state.parents[name];
    if (parent) {
      const bone = new THREE.Mesh(boneGeometry, materials[side(name)]);
      skeleton.add(bone);
      boneMeshes.set(name, bone);
    }
    const ring = new THREE.Mesh(pinRingGeometry, materials.pin);
    ring.visible = false;
    skeleton.add(ring);
    pinRings.set(name, ring);
  }
}

export const UP = new THREE.Vector3(0, 1, 0);
const tmpA = new THREE.Vector3();
const tmpB = new THREE.Vector3();

// The open file's own bones: one thin grey cylinder per joint with a parent.
const characterBones = new THREE.Group();
scene.add(characterBones);
const ownBoneMaterial = new THREE.MeshStandardMaterial({ color: 0x9aa3b5, roughness: 0.6 });
const ownJointGeometry = new THREE.SphereGeometry(0.011, 12, 8);

export function buildCharacterBones() {
  characterBones.clear();
  doc.drawn = { row: null };
  if (!doc.active) return;
  for (const j of doc.info.joints) {
    if (j.parent >= 0) characterBones.add(new THREE.Mesh(boneGeometry, ownBoneMaterial));
    else characterBones.add(new THREE.Mesh(ownJointGeometry, ownBoneMaterial));
  }
}

function placeBone(bone, a, b, radius) {
  tmpA.set(a[0], a[1], a[2]);
  tmpB.set(b[0], b[1], b[2]);
  const length = tmpA.distanceTo(tmpB);
  bone.position.copy(tmpA).add(tmpB).multiplyScalar(0.5);
  bone.scale.set(radius, Math.max(length, 1e-6), radius);
  if (length > 1e-9) bone.quaternion.setFromUnitVectors(UP, tmpB.sub(tmpA).divideScalar(length));
}

// The same values (a row of a text read whole is a view of its values: the same view
// again). Compared, not the texts: a new answer's text compared with the one drawn before
// (as long, all but a line alike) was copied whole to be compared, 3-4 ms a 7.5 MB answer.
const sameRow = (a, b) => a === b || (a !== null && a.buffer === b.buffer && a.byteOffset === b.byteOffset);

function drawCharacter() {
  characterBones.visible = doc.active;
  if (!doc.active) return;
  const row = fileRow(doc.shown, doc.frame);
  if (sameRow(doc.drawn.row, row)) return;
  const { fk } = rowFrame(row);
  doc.world = fk.pos.map(toWorld);
  doc.info.joints.forEach((j, i) => {
    const mesh = characterBones.children[i];
    if (j.parent >= 0) placeBone(mesh, doc.world[j.parent], doc.world[i], 0.45);
    else mesh.position.set(...doc.world[i]);
  });
  doc.drawn = { row };
}

// A target's marker: its hidden part's faint pass over the body (renderOrder 5, after it),
// then its seen part, depth-tested, over that (6; the selection ring, 10, over both).
function targetMarker() {
  const marker = new THREE.Group();
  const hidden = new THREE.Mesh(sphereGeometry, materials.targetHidden);
  hidden.renderOrder = 5;
  const seen = new THREE.Mesh(sphereGeometry, materials.target);
  seen.renderOrder = 6;
  marker.add(hidden, seen);
  marker.scale.setScalar(TARGET_RADIUS);
  return marker;
}

export function drawPose() {
  const pose = state.pose;
  if (!pose) return;
  for (const [name, mesh] of jointMeshes) {
    const p = pose[name];
    if (!p) continue;
    mesh.position.set(p[0], p[1], p[2]);
    const pinned = state.pins.has(name);
    mesh.material = name === ui.hovered ? materials.hover : pinned ? materials.pin : materials[side(name)];
    const ring = pinRings.get(name);
    ring.visible = pinned;
    ring.position.copy(mesh.position);
    ring.quaternion.copy(camera.quaternion); // face the camera
  }
  const selected = ui.selected && pose[ui.selected];
  selectionRing.visible = Boolean(selected) && selected.every(Number.isFinite);
  if (selectionRing.visible) {
    selectionRing.position.set(selected[0], selected[1], selected[2]);
    selectionRing.scale.setScalar(Math.max(1, (handleRadius(ui.selected) + 0.025) / SELECTION_RADIUS));
    selectionRing.quaternion.copy(camera.quaternion);
  }
  for (const [child, bone] of boneMeshes) {
    bone.visible = !doc.active; // a file shows its own bones instead
    placeBone(bone, pose[state.parents[child]], pose[child], 1);
  }
  drawCharacter();
  // Targets: a red marker each, and a thin line to its joint while it is not reached.
  for (const [joint, marker] of targetMarkers) {
    if (!state.targets.has(joint)) {
      const line = targetLines.get(joint);
      scene.remove(marker);
      scene.remove(line);
      line.geometry.dispose(); // (its own: a target removed kept its line's buffers)
      line.material.dispose();
      targetMarkers.delete(joint);
      targetLines.delete(joint);
    }
  }
  for (const [joint, pos] of state.targets) {
    let marker = targetMarkers.get(joint);
    if (!marker) {
      marker = targetMarker();
      scene.add(marker);
      targetMarkers.set(joint, marker);
      const line = new THREE.Line(
        new THREE.BufferGeometry().setFromPoints([new THREE.Vector3(), new THREE.Vector3()]),
        new THREE.LineBasicMaterial({ color: COLORS.target }),
      );
      scene.add(line);
      targetLines.set(joint, line);
    }
    marker.position.set(pos[0], pos[1], pos[2]);
    const j = pose[joint];
    const inside = Math.hypot(pos[0] - j[0], pos[1] - j[1], pos[2] - j[2]) + TARGET_RADIUS <= handleRadius(joint);
    marker.children[1].material = inside ? materials.targetOver : materials.target;
    const line = targetLines.get(joint);
    line.geometry.attributes.position.setXYZ(0, pos[0], pos[1], pos[2]);
    line.geometry.attributes.position.setXYZ(1, j[0], j[1], j[2]);
    line.geometry.attributes.position.needsUpdate = true;
    line.geometry.computeBoundingSphere();
  }
  ui.needsRender = true;
}

// The view's size, and its pixels as the screen's: the device pixel ratio is read anew each
// time and followed as it changes (the browser zoomed, the window moved to a screen of
// another density: ``followRatio``). It was read once, at start: zoomed
// in, or on a HiDPI screen after, the view was drawn at the old ratio and stretched, blurred.
export function resize() {
  const w = viewport.clientWidth || 1;
  const h = viewport.clientHeight || 1;
  const ratio = Math.min(window.devicePixelRatio, 2);
  if (renderer.getPixelRatio() !== ratio) renderer.setPixelRatio(ratio);
  renderer.setSize(w, h, false);
  renderer.domElement.style.width = `${w}px`;
  renderer.domElement.style.height = `${h}px`;
  camera.aspect = w / h;
  camera.updateProjectionMatrix();
  ui.needsRender = true;
}
new ResizeObserver(resize).observe(viewport);
// (each animation frame, editor.js: a ratio changed with no change of size fires no
// ResizeObserver, and Chromium's matchMedia on the ratio did not fire either)
export function followRatio() {
  if (renderer.getPixelRatio() !== Math.min(window.devicePixelRatio, 2)) resize();
}
controls.addEventListener('change', () => {
  ui.needsRender = true;
});
