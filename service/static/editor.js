// Marionette pose editor: drag joints, the service answers with a full-body pose.
//
// Frame: metres, +Y up, the character faces +Z, its left is +X (glTF). The camera starts
// in front of the character (+Z side), so its left appears on the right of the screen.
//
// Solving: every edit marks the solve "dirty"; the animation-frame loop sends one
// /v1/solve when the previous one has come back (at most one in flight, always with the
// latest targets: throttled to the frame rate, latest wins, never a queue). Every solve
// starts from the *committed* pose (the pose before the current gesture), so a gesture
// cannot drift; the final answer of a gesture is committed and goes into the undo history.
//
// A BVH file (Open BVH..., or dropped on the page) is shown with its OWN bones (every joint
// of the file, thin grey) and the 21 canonical joints as handles, placed by the service's
// joint map (POST v1/bvh/inspect). Dragging solves with POST v1/bvh/solve (the whole file,
// the frame, targets in the file's units and axes) and the answer's `bvh` becomes the file;
// the frame slider scrubs; Export downloads the edited file. The page's world is the file's
// mapped to metres, +Y up, the character (as opened) facing +Z on the grid.
//
// Tests read the page through `window.marionette` (read-only).

import * as THREE from 'three';
import { OrbitControls } from 'three/addons/controls/OrbitControls.js';
import { anchorPoints, forwardKinematics, parseMotion } from './bvh.js';

// ------------------------------------------------------------------------------------
// Skeleton (replaced by GET v1/skeleton once the server answers)
// ------------------------------------------------------------------------------------
const FALLBACK_PARENTS = {
  pelvis: null, spine1: 'pelvis', spine2: 'spine1', neck: 'spine2', head: 'neck',
  left_collar: 'spine2', left_shoulder: 'left_collar', left_elbow: 'left_shoulder',
  left_wrist: 'left_elbow', right_collar: 'spine2', right_shoulder: 'right_collar',
  right_elbow: 'right_shoulder', right_wrist: 'right_elbow', left_hip: 'pelvis',
  left_knee: 'left_hip', left_ankle: 'left_knee', left_foot: 'left_ankle',
  right_hip: 'pelvis', right_knee: 'right_hip', right_ankle: 'right_knee',
  right_foot: 'right_ankle',
};

const COLORS = {
  left: 0x3b82f6,
  right: 0xf59e0b,
  centre: 0xc3c8d2,
  pin: 0xa855f7,
  target: 0xef4444,
  hover: 0xffffff,
};
const JOINT_RADIUS = 0.026;
const BONE_RADIUS = 0.016;
const HEAD_RADIUS = 0.075;
const PICK_PIXELS = 18;

const $ = (id) => document.getElementById(id);

// ------------------------------------------------------------------------------------
// API helper: every call goes through here; failures become ApiError and are shown.
// ------------------------------------------------------------------------------------
class ApiError extends Error {
  constructor(status, title, detail, requestId = null) {
    super(`${title}: ${detail}`);
    this.status = status;
    this.title = title;
    this.detail = detail;
    this.requestId = requestId;
  }
}

function apiKey() {
  return $('api-key').value.trim();
}

async function api(method, path, body) {
  const headers = { Accept: 'application/json, application/problem+json' };
  if (body !== undefined) headers['Content-Type'] = 'application/json';
  const key = apiKey();
  if (key) headers['X-API-Key'] = key;
  const t0 = performance.now();
  let res;
  try {
    res = await fetch(path, {
      method,
      headers,
      body: body === undefined ? undefined : JSON.stringify(body),
      cache: 'no-store',
    });
  } catch (err) {
    throw new ApiError(0, 'Server unreachable', `${method} /${path} failed (${err.message})`);
  }
  const text = await res.text();
  const rtt = performance.now() - t0;
  let data = null;
  try {
    data = text ? JSON.parse(text) : null;
  } catch {
    data = null;
  }
  const requestId = res.headers.get('X-Request-ID');
  if (!res.ok) {
    const title = (data && data.title) || `HTTP ${res.status}`;
    const detail = (data && data.detail) || text.slice(0, 300) || res.statusText;
    throw new ApiError(res.status, title, detail, requestId);
  }
  if (data === null) {
    throw new ApiError(res.status, 'Bad response', `${method} /${path}: the body is not JSON`, requestId);
  }
  return { data, rtt, serverTime: res.headers.get('X-Total-Time') || res.headers.get('X-Inference-Time'), requestId };
}

// ------------------------------------------------------------------------------------
// Error banner
// ------------------------------------------------------------------------------------
let currentError = null;

function showError(err) {
  const e = err instanceof ApiError ? err : new ApiError(-1, 'Editor error', String(err && err.message || err));
  currentError = {
    status: e.status,
    title: e.title,
    detail: e.detail,
    requestId: e.requestId,
  };
  $('error-title').textContent = e.status > 0 ? `${e.status} ${e.title}` : e.title;
  $('error-detail').textContent = e.detail;
  $('error-meta').textContent = e.requestId ? `request id ${e.requestId}` : '';
  $('error').hidden = false;
}

function clearError() {
  currentError = null;
  $('error').hidden = true;
}

// ------------------------------------------------------------------------------------
// State
// ------------------------------------------------------------------------------------
const state = {
  joints: Object.keys(FALLBACK_PARENTS),
  parents: { ...FALLBACK_PARENTS },
  samples: [],
  sample: 0,
  committed: null, // pose the solves start from
  pose: null, // pose on screen
  targets: new Map(), // joint -> [x, y, z]
  pins: new Set(),
  model: null,
};

const solver = {
  dirty: false, // an edit is waiting to be solved
  inflight: false,
  epoch: 0, // bumped by undo/redo/reset/sample: answers of older epochs are dropped
  commitPending: false, // commit the answer to the latest edit (end of a gesture)
  sent: 0,
  answered: 0,
  last: null,
  latencies: [],
};

// The open BVH file (doc.active). doc.text is the committed file (solves start from it),
// doc.shown the file whose frame is on screen (the latest answer during a gesture).
const doc = {
  active: false,
  name: '',
  original: '', // as opened (Reset)
  text: '',
  shown: '',
  info: null, // the v1/bvh/inspect answer: joints, anchors, units, up, frames, ...
  frame: 0,
  toWorld: new THREE.Matrix4(),
  fromWorld: new THREE.Matrix4(),
  tried: null, // {text, name} of the last file opened (re-opened when units / up change)
  drawn: { text: null, frame: -1 }, // what the character's bones show
  world: [], // world positions of every joint of the file, as drawn
};
const motionCache = new Map(); // text -> MOTION values (the last few texts)

function motionOf(text) {
  let values = motionCache.get(text);
  if (!values) {
    values = parseMotion(text);
    motionCache.set(text, values);
    if (motionCache.size > 6) motionCache.delete(motionCache.keys().next().value);
  }
  return values;
}

// Forward kinematics of one frame of a text: every joint, and the canonical points (file units).
function fileFrame(text, frame) {
  const joints = doc.info.joints;
  const n = joints.reduce((acc, j) => acc + j.channels.length, 0);
  const row = motionOf(text).subarray(frame * n, (frame + 1) * n);
  const fk = forwardKinematics(joints, row);
  return { fk, points: anchorPoints(joints, doc.info.anchors, fk) };
}

const toWorld = (p) => new THREE.Vector3(p[0], p[1], p[2]).applyMatrix4(doc.toWorld).toArray();
const toFile = (p) => new THREE.Vector3(p[0], p[1], p[2]).applyMatrix4(doc.fromWorld).toArray();

// The 21 handles (world) of a frame of a text.
function filePose(text, frame) {
  const { points } = fileFrame(text, frame);
  return Object.fromEntries(Object.entries(points).map(([k, p]) => [k, toWorld(p)]));
}

const clonePose = (pose) => Object.fromEntries(Object.entries(pose).map(([k, v]) => [k, [...v]]));

function snapshot() {
  const snap = {
    pose: clonePose(state.committed),
    targets: [...state.targets].map(([j, p]) => [j, [...p]]),
    pins: [...state.pins],
  };
  if (doc.active) {
    snap.text = doc.text; // shared, not copied: a string is immutable
    snap.frame = doc.frame;
  }
  return snap;
}

function restore(snap) {
  state.committed = clonePose(snap.pose);
  state.pose = clonePose(snap.pose);
  state.targets = new Map(snap.targets.map(([j, p]) => [j, [...p]]));
  state.pins = new Set(snap.pins);
  if (doc.active && snap.text !== undefined) {
    doc.text = snap.text;
    doc.shown = snap.text;
    doc.frame = snap.frame;
  }
}

function sameSnapshot(a, b) {
  if (!a || a.text !== b.text || a.frame !== b.frame) return false;
  return JSON.stringify({ ...a, text: null }) === JSON.stringify({ ...b, text: null });
}

// The pose on screen becomes the committed one (solves start from it).
function commitShown() {
  state.committed = clonePose(state.pose);
  doc.text = doc.shown;
}

const history = { stack: [], index: -1 };

function pushHistory() {
  const snap = snapshot();
  const top = history.stack[history.index];
  if (sameSnapshot(top, snap)) {
    updateButtons(); // nothing changed (e.g. an option toggled with no targets)
    return;
  }
  history.stack.length = history.index + 1;
  history.stack.push(snap);
  if (history.stack.length > 200) history.stack.shift();
  history.index = history.stack.length - 1;
  updateButtons();
}

function cancelSolves() {
  solver.epoch += 1;
  solver.dirty = false;
  solver.commitPending = false;
}

function undo() {
  if (history.index <= 0) return;
  endDrag(false);
  cancelSolves();
  history.index -= 1;
  restore(history.stack[history.index]);
  refresh();
}

function redo() {
  if (history.index >= history.stack.length - 1) return;
  endDrag(false);
  cancelSolves();
  history.index += 1;
  restore(history.stack[history.index]);
  refresh();
}

function loadSample(i) {
  endDrag(false);
  cancelSolves();
  if (doc.active) closeFile();
  state.sample = i;
  hovered = null;
  $('hud').hidden = true;
  const pose = state.samples[i].pose;
  restore({ pose, targets: [], pins: [] });
  pushHistory();
  $('sample').value = String(i);
  refresh();
}

function reset() {
  if (!doc.active) {
    loadSample(state.sample);
    return;
  }
  endDrag(false);
  cancelSolves();
  doc.text = doc.original;
  restore({ pose: filePose(doc.original, doc.frame), targets: [], pins: [], text: doc.original, frame: doc.frame });
  pushHistory();
  refresh();
}

function options() {
  return {
    method: document.querySelector('input[name=method]:checked').value,
    preserve_bone_lengths: $('preserve').checked,
    reach: $('exact').checked ? 'exact' : 'soft',
    tolerance: $('tolerance').valueAsNumber,
  };
}

function solveBody() {
  if (doc.active) {
    return {
      bvh: doc.text,
      frame: doc.frame,
      units: doc.info.units,
      up: doc.info.up,
      targets: [...state.targets].map(([joint, p]) => ({ joint, position: toFile(p), weight: 1.0 })),
      pins: [...state.pins].filter((j) => !state.targets.has(j)),
      options: options(),
    };
  }
  return {
    pose: state.committed,
    targets: [...state.targets].map(([joint, position]) => ({ joint, position, weight: 1.0 })),
    pins: [...state.pins].filter((j) => !state.targets.has(j)),
    options: options(),
  };
}

// An edit happened: solve it on the next frame (commit = it ends a gesture).
function requestSolve(commit) {
  if (commit) solver.commitPending = true;
  if (state.targets.size === 0) {
    // Nothing to reach: the committed pose stands.
    solver.dirty = false;
    state.pose = clonePose(state.committed);
    doc.shown = doc.text;
    if (solver.commitPending) {
      solver.commitPending = false;
      pushHistory();
    }
    refresh();
    return;
  }
  solver.dirty = true;
}

async function sendSolve() {
  solver.dirty = false;
  solver.inflight = true;
  const epoch = solver.epoch;
  const commit = solver.commitPending;
  const body = solveBody();
  solver.sent += 1;
  $('solve-count').textContent = String(solver.sent);
  try {
    const res = await api('POST', body.bvh === undefined ? 'v1/solve' : 'v1/bvh/solve', body);
    if (epoch !== solver.epoch) return; // undone / reset / scrubbed meanwhile
    solver.answered += 1;
    if (body.bvh === undefined) {
      state.pose = res.data.pose;
    } else {
      doc.shown = res.data.bvh;
      state.pose = filePose(doc.shown, body.frame);
    }
    state.model = res.data.model;
    const server = parseFloat(res.serverTime);
    solver.latencies.push(server);
    if (solver.latencies.length > 50) solver.latencies.shift();
    solver.last = {
      request: body,
      response: res.data,
      serverTime: res.serverTime,
      serverMs: server,
      rttMs: res.rtt,
      requestId: res.requestId,
    };
    clearError();
    if (commit && !solver.dirty && solver.commitPending && !drag) {
      commitShown();
      solver.commitPending = false;
      pushHistory();
    }
    refresh();
  } catch (err) {
    if (epoch !== solver.epoch) return;
    if (commit && !solver.dirty) {
      // The gesture's final solve failed: keep its targets (so it can be retried) but not
      // a pose the server never produced.
      solver.commitPending = false;
      pushHistory();
    }
    showError(err);
    refresh();
  } finally {
    solver.inflight = false;
  }
}

// ------------------------------------------------------------------------------------
// Scene
// ------------------------------------------------------------------------------------
const viewport = $('viewport');
let renderer;
try {
  renderer = new THREE.WebGLRenderer({ antialias: true, preserveDrawingBuffer: true });
} catch (err) {
  showError(new ApiError(-1, 'WebGL unavailable', `the 3D view cannot start: ${err.message}`));
  throw err;
}
renderer.setPixelRatio(Math.min(window.devicePixelRatio, 2));
viewport.appendChild(renderer.domElement);

const scene = new THREE.Scene();
scene.background = new THREE.Color(0x1c2028);
const camera = new THREE.PerspectiveCamera(38, 1, 0.05, 100);
camera.position.set(0.75, 1.3, 2.9);

scene.add(new THREE.HemisphereLight(0xffffff, 0x404552, 2.2));
const sun = new THREE.DirectionalLight(0xffffff, 2.0);
sun.position.set(2, 4, 3);
scene.add(sun);

// Floor: a 4 m grid of 25 cm squares.
scene.add(new THREE.GridHelper(4, 16, 0x6b7280, 0x394050));

// Facing arrow on the floor (+Z, towards the default camera).
const facing = new THREE.ArrowHelper(new THREE.Vector3(0, 0, 1), new THREE.Vector3(0, 0.003, 0.15), 0.25, 0x6b7280, 0.07, 0.045);
scene.add(facing);

const controls = new OrbitControls(camera, renderer.domElement);
controls.target.set(0, 0.85, 0);
controls.enableDamping = false;
controls.update();

const side = (name) => (name.startsWith('left_') ? 'left' : name.startsWith('right_') ? 'right' : 'centre');
const materials = {
  left: new THREE.MeshStandardMaterial({ color: COLORS.left, roughness: 0.5 }),
  right: new THREE.MeshStandardMaterial({ color: COLORS.right, roughness: 0.5 }),
  centre: new THREE.MeshStandardMaterial({ color: COLORS.centre, roughness: 0.5 }),
  pin: new THREE.MeshStandardMaterial({ color: COLORS.pin, roughness: 0.4, emissive: 0x3b0764 }),
  target: new THREE.MeshStandardMaterial({ color: COLORS.target, roughness: 0.4, emissive: 0x450a0a, transparent: true, opacity: 0.85 }),
  hover: new THREE.MeshStandardMaterial({ color: COLORS.hover, roughness: 0.3, emissive: 0x555555 }),
};
const sphereGeometry = new THREE.SphereGeometry(1, 24, 16);
const boneGeometry = new THREE.CylinderGeometry(BONE_RADIUS, BONE_RADIUS, 1, 16, 1);
const pinRingGeometry = new THREE.TorusGeometry(0.045, 0.007, 8, 32);

const skeleton = new THREE.Group();
scene.add(skeleton);
const jointMeshes = new Map();
const boneMeshes = new Map(); // child -> mesh
const pinRings = new Map();
const targetMarkers = new Map();
const targetLines = new Map();

function buildSkeleton() {
  skeleton.clear();
  jointMeshes.clear();
  boneMeshes.clear();
  pinRings.clear();
  for (const name of state.joints) {
    const mesh = new THREE.Mesh(sphereGeometry, materials[side(name)]);
    const r = name === 'head' && !doc.active ? HEAD_RADIUS : JOINT_RADIUS;
    mesh.scale.setScalar(r);
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

const UP = new THREE.Vector3(0, 1, 0);
const tmpA = new THREE.Vector3();
const tmpB = new THREE.Vector3();

// The open file's own bones: one thin grey cylinder per joint with a parent.
const characterBones = new THREE.Group();
scene.add(characterBones);
const ownBoneMaterial = new THREE.MeshStandardMaterial({ color: 0x9aa3b5, roughness: 0.6 });
const ownJointGeometry = new THREE.SphereGeometry(0.011, 12, 8);

function buildCharacterBones() {
  characterBones.clear();
  doc.drawn = { text: null, frame: -1 };
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

function drawCharacter() {
  characterBones.visible = doc.active;
  if (!doc.active || (doc.drawn.text === doc.shown && doc.drawn.frame === doc.frame)) return;
  const { fk } = fileFrame(doc.shown, doc.frame);
  doc.world = fk.pos.map(toWorld);
  doc.info.joints.forEach((j, i) => {
    const mesh = characterBones.children[i];
    if (j.parent >= 0) placeBone(mesh, doc.world[j.parent], doc.world[i], 0.45);
    else mesh.position.set(...doc.world[i]);
  });
  doc.drawn = { text: doc.shown, frame: doc.frame };
}

let hovered = null;
let needsRender = true;

function drawPose() {
  const pose = state.pose;
  if (!pose) return;
  for (const [name, mesh] of jointMeshes) {
    const p = pose[name];
    if (!p) continue;
    mesh.position.set(p[0], p[1], p[2]);
    const pinned = state.pins.has(name);
    mesh.material = name === hovered ? materials.hover : pinned ? materials.pin : materials[side(name)];
    const ring = pinRings.get(name);
    ring.visible = pinned;
    ring.position.copy(mesh.position);
    ring.quaternion.copy(camera.quaternion); // face the camera
  }
  for (const [child, bone] of boneMeshes) {
    bone.visible = !doc.active; // a file shows its own bones instead
    placeBone(bone, pose[state.parents[child]], pose[child], 1);
  }
  drawCharacter();
  // Targets: a red marker each, and a thin line to its joint while it is not reached.
  for (const [joint, marker] of targetMarkers) {
    if (!state.targets.has(joint)) {
      scene.remove(marker);
      scene.remove(targetLines.get(joint));
      targetMarkers.delete(joint);
      targetLines.delete(joint);
    }
  }
  for (const [joint, pos] of state.targets) {
    let marker = targetMarkers.get(joint);
    if (!marker) {
      marker = new THREE.Mesh(sphereGeometry, materials.target);
      marker.scale.setScalar(0.036);
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
    const line = targetLines.get(joint);
    const j = pose[joint];
    line.geometry.attributes.position.setXYZ(0, pos[0], pos[1], pos[2]);
    line.geometry.attributes.position.setXYZ(1, j[0], j[1], j[2]);
    line.geometry.attributes.position.needsUpdate = true;
    line.geometry.computeBoundingSphere();
  }
  needsRender = true;
}

function resize() {
  const w = viewport.clientWidth || 1;
  const h = viewport.clientHeight || 1;
  renderer.setSize(w, h, false);
  renderer.domElement.style.width = `${w}px`;
  renderer.domElement.style.height = `${h}px`;
  camera.aspect = w / h;
  camera.updateProjectionMatrix();
  needsRender = true;
}
new ResizeObserver(resize).observe(viewport);
controls.addEventListener('change', () => {
  needsRender = true;
});

// ------------------------------------------------------------------------------------
// Screen-space picking and ray-plane dragging
// ------------------------------------------------------------------------------------
function toScreen(p) {
  const v = new THREE.Vector3(p[0], p[1], p[2]).project(camera);
  const rect = renderer.domElement.getBoundingClientRect();
  return {
    x: rect.left + ((v.x + 1) / 2) * rect.width,
    y: rect.top + ((1 - v.y) / 2) * rect.height,
    depth: v.z,
  };
}

// The nearest joint or target marker within PICK_PIXELS of the pointer (targets first).
function pick(clientX, clientY) {
  let best = null;
  const consider = (kind, joint, p, bias) => {
    const s = toScreen(p);
    if (s.depth < -1 || s.depth > 1) return;
    const d = Math.hypot(s.x - clientX, s.y - clientY) - bias;
    if (d <= PICK_PIXELS && (!best || d < best.d)) best = { kind, joint, d };
  };
  for (const [joint, p] of state.targets) consider('target', joint, p, 2);
  for (const joint of state.joints) {
    const bias = joint === 'head' && !doc.active ? 10 : 0;
    if (state.pose && state.pose[joint]) consider('joint', joint, state.pose[joint], bias);
  }
  return best;
}

const raycaster = new THREE.Raycaster();
let drag = null;

function pointerRay(clientX, clientY) {
  const rect = renderer.domElement.getBoundingClientRect();
  const ndc = new THREE.Vector2(
    ((clientX - rect.left) / rect.width) * 2 - 1,
    -((clientY - rect.top) / rect.height) * 2 + 1,
  );
  raycaster.setFromCamera(ndc, camera);
  return raycaster.ray;
}

function onPointerDown(ev) {
  if (ev.button !== 0 || !state.pose) return;
  const hit = pick(ev.clientX, ev.clientY);
  if (!hit) return; // empty space: OrbitControls gets the event
  ev.stopPropagation();
  ev.preventDefault();
  const { joint } = hit;
  if (ev.altKey) {
    if (state.targets.has(joint)) removeTarget(joint);
    return;
  }
  if (ev.shiftKey) {
    togglePin(joint);
    return;
  }
  // Drag in the plane through the grabbed point, facing the camera.
  const start = hit.kind === 'target' ? state.targets.get(joint) : state.pose[joint];
  const point = new THREE.Vector3(start[0], start[1], start[2]);
  const normal = new THREE.Vector3();
  camera.getWorldDirection(normal);
  const ray = pointerRay(ev.clientX, ev.clientY);
  const plane = new THREE.Plane().setFromNormalAndCoplanarPoint(normal, point);
  const grabbed = new THREE.Vector3();
  const offset = ray.intersectPlane(plane, grabbed) ? point.clone().sub(grabbed) : new THREE.Vector3();
  drag = { joint, plane, offset, moved: false, before: snapshot(), hadTarget: state.targets.has(joint), pointerId: ev.pointerId };
  controls.enabled = false;
  viewport.style.cursor = 'grabbing';
}

function onPointerMove(ev) {
  if (!drag) {
    updateHover(ev);
    return;
  }
  const ray = pointerRay(ev.clientX, ev.clientY);
  const hitPoint = new THREE.Vector3();
  if (!ray.intersectPlane(drag.plane, hitPoint)) return;
  hitPoint.add(drag.offset);
  if (!drag.moved) {
    drag.moved = true;
    state.pins.delete(drag.joint); // a dragged joint follows its target, not its pin
  }
  state.targets.set(drag.joint, [hitPoint.x, hitPoint.y, hitPoint.z]);
  requestSolve(false);
  refreshPanel();
  drawPose();
  moveHud(ev.clientX, ev.clientY, drag.joint);
}

function onPointerUp() {
  if (drag) endDrag(true);
}

// End the gesture: commit its last solve, or (cancel) go back to where it started.
function endDrag(commit) {
  if (!drag) return;
  const d = drag;
  drag = null;
  controls.enabled = true;
  viewport.style.cursor = '';
  if (!d.moved) return; // a click, not a drag
  if (commit) {
    requestSolve(true);
  } else {
    cancelSolves();
    restore(d.before);
    refresh();
  }
}

function updateHover(ev) {
  const hit = ev.target === renderer.domElement ? pick(ev.clientX, ev.clientY) : null;
  const name = hit ? hit.joint : null;
  viewport.style.cursor = hit ? 'grab' : '';
  if (name !== hovered) {
    hovered = name;
    drawPose();
  }
  if (hit) moveHud(ev.clientX, ev.clientY, hit.kind === 'target' ? `target: ${name}` : name);
  else $('hud').hidden = true;
}

function moveHud(x, y, text) {
  const hud = $('hud');
  const anchor = doc.active && doc.info.anchors[text];
  hud.textContent = anchor ? `${text} (${anchor.label})` : text;
  hud.style.left = `${x + 14}px`;
  hud.style.top = `${y + 10}px`;
  hud.hidden = false;
}

function togglePin(joint) {
  if (state.pins.has(joint)) {
    state.pins.delete(joint);
  } else {
    state.pins.add(joint);
    if (state.targets.delete(joint)) {
      // It was targeted: it now stays where the last solve put it.
      commitShown();
    }
  }
  requestSolve(true);
  refresh();
}

function removeTarget(joint) {
  state.targets.delete(joint);
  commitShown();
  requestSolve(true);
  refresh();
}

function clearTargets() {
  if (state.targets.size === 0) return;
  cancelSolves();
  state.targets.clear();
  commitShown();
  requestSolve(true);
}

// ------------------------------------------------------------------------------------
// Panel
// ------------------------------------------------------------------------------------
function fmtMm(m) {
  return `${(m * 1000).toFixed(1)} mm`;
}

function refreshPanel() {
  const last = solver.last;
  const byJoint = new Map((last ? last.response.targets : []).map((t) => [t.joint, t]));
  const tbody = $('targets').querySelector('tbody');
  tbody.replaceChildren();
  for (const joint of state.targets.keys()) {
    const tr = document.createElement('tr');
    tr.dataset.joint = joint;
    const result = byJoint.get(joint);
    const cells = [
      [joint, ''],
      [result ? fmtMm(result.error) : '–', 'err'],
      [result ? (result.reached ? '✓' : '✗') : '', result ? (result.reached ? 'ok' : 'miss') : ''],
    ];
    for (const [text, cls] of cells) {
      const td = document.createElement('td');
      td.textContent = text;
      if (cls) td.className = cls;
      tr.appendChild(td);
    }
    const td = document.createElement('td');
    const btn = document.createElement('button');
    btn.type = 'button';
    btn.textContent = '×';
    btn.title = `Remove the target of ${joint}`;
    btn.addEventListener('click', () => removeTarget(joint));
    td.appendChild(btn);
    tr.appendChild(td);
    tbody.appendChild(tr);
  }
  $('no-targets').hidden = state.targets.size > 0;
  $('pins').textContent = state.pins.size ? [...state.pins].join(', ') : 'none';
  if (last) {
    const med = [...solver.latencies].sort((a, b) => a - b)[Math.floor(solver.latencies.length / 2)];
    $('latency').textContent = `${last.serverMs.toFixed(2)} ms (median ${med.toFixed(2)})`;
    $('latency').title = 'X-Total-Time of the last solve (the server, arrival to answer); median of the last 50';
    $('rtt').textContent = `${last.rttMs.toFixed(1)} ms`;
    const r = last.response;
    $('solve-method').textContent = r.iterations ? `${r.method}, ${r.iterations} FABRIK it.` : r.method;
    $('solvers').textContent = r.solvers.join(' → ') || '–';
    $('bone-error').textContent = r.max_bone_length_error === undefined
      ? 'the file\'s own' // BVH: rotations only, offsets untouched
      : `${(r.max_bone_length_error * 100).toPrecision(2)} %`;
  }
  $('model').textContent = `model: ${state.model || '–'}`;
  updateButtons();
}

function updateButtons() {
  $('undo').disabled = history.index <= 0;
  $('redo').disabled = history.index >= history.stack.length - 1;
  $('clear-targets').disabled = state.targets.size === 0;
}

function refresh() {
  drawPose();
  refreshPanel();
  refreshFrame();
}

function exportDocument() {
  if (doc.active) {
    return { format: 'bvh', name: exportName(), frame: doc.frame, bvh: doc.text };
  }
  return {
    format: 'marionette-pose',
    version: 1,
    frame: { units: 'metres', up: '+Y', forward: '+Z', left: '+X' },
    pose: clonePose(state.pose),
    targets: [...state.targets].map(([joint, position]) => ({ joint, position: [...position] })),
    pins: [...state.pins],
    options: options(),
    model: state.model,
    sample: state.samples[state.sample] ? state.samples[state.sample].name : null,
  };
}

function exportName() {
  return `${doc.name.replace(/\.bvh$/i, '')}-edited.bvh`;
}

function exportPose() {
  const blob = doc.active
    ? new Blob([doc.text], { type: 'text/plain' })
    : new Blob([JSON.stringify(exportDocument(), null, 2)], { type: 'application/json' });
  const url = URL.createObjectURL(blob);
  const a = document.createElement('a');
  a.href = url;
  a.download = doc.active ? exportName() : 'marionette-pose.json';
  document.body.appendChild(a);
  a.click();
  a.remove();
  setTimeout(() => URL.revokeObjectURL(url), 1000);
}

// ------------------------------------------------------------------------------------
// BVH files: open (picker or drop), scrub, close
// ------------------------------------------------------------------------------------
function fileSettings() {
  const units = $('bvh-units').value;
  const up = $('bvh-up').value;
  const out = {};
  if (units !== 'auto') out.units = Number.isFinite(Number(units)) ? Number(units) : units;
  if (up !== 'auto') out.up = up;
  return out;
}

// The page's world: metres, +Y up, the character as opened facing +Z with its pelvis
// above the origin and its lowest joint on the grid.
function worldMapping(info, frame0) {
  const s = info.metres_per_unit;
  const m = new THREE.Matrix4().makeScale(s, s, s);
  if (info.up === '+Z') m.premultiply(new THREE.Matrix4().makeRotationX(-Math.PI / 2)); // (x, y, z) -> (x, z, -y)
  const at = (p) => new THREE.Vector3(...p).applyMatrix4(m);
  const left = at(frame0.points.left_hip).sub(at(frame0.points.right_hip));
  const forward = new THREE.Vector3().crossVectors(left, UP);
  const yaw = Math.atan2(forward.x, forward.z);
  m.premultiply(new THREE.Matrix4().makeRotationY(-yaw));
  const pelvis = at(frame0.points.pelvis);
  const lowest = Math.min(...frame0.fk.pos.map((p) => at(p).y));
  m.premultiply(new THREE.Matrix4().makeTranslation(-pelvis.x, -lowest, -pelvis.z));
  return m;
}

let opening = 0;

async function openText(text, name) {
  doc.tried = { text, name };
  const ticket = ++opening;
  $('status').textContent = `opening ${name}…`;
  let res;
  try {
    res = await api('POST', 'v1/bvh/inspect', { bvh: text, frame: 0, ...fileSettings() });
    if (ticket !== opening) return;
  } catch (err) {
    if (ticket !== opening) return;
    showError(err);
    $('status').textContent = connected ? 'connected' : 'server not ready';
    return;
  }
  endDrag(false);
  cancelSolves();
  motionCache.clear();
  const info = res.data;
  Object.assign(doc, { active: true, name, original: text, text, shown: text, info, frame: 0 });
  const frame0 = fileFrame(text, 0);
  doc.toWorld = worldMapping(info, frame0);
  doc.fromWorld = doc.toWorld.clone().invert();
  buildSkeleton();
  buildCharacterBones();
  hovered = null;
  history.stack = [];
  history.index = -1;
  restore({ pose: filePose(text, 0), targets: [], pins: [], text, frame: 0 });
  pushHistory();
  const pelvis = state.pose.pelvis;
  controls.target.set(0, pelvis[1], 0);
  camera.position.set(0.85, pelvis[1] + 0.5, 3.3);
  controls.update();
  const slider = $('bvh-frame');
  slider.max = String(Math.max(info.frames - 1, 0));
  slider.value = '0';
  $('bvh-loaded').hidden = false;
  $('bvh-name').textContent = name;
  const fps = info.frame_time > 0 ? ` @ ${(1 / info.frame_time).toFixed(4).replace(/\.?0+$/, '')} fps` : '';
  $('bvh-meta').textContent = `${info.joints.length} joints, ${info.frames} frames${fps}; `
    + `${info.scheme} map, units ${info.units}, up ${info.up}`;
  $('export').textContent = 'Export BVH';
  $('export').title = 'Download the edited BVH file';
  $('sample').value = '';
  $('status').textContent = connected ? 'connected' : 'server not ready';
  clearError();
  refresh();
}

async function openFile(file) {
  if (!file) return;
  let text;
  try {
    text = await file.text();
  } catch (err) {
    showError(new ApiError(-1, 'Cannot read the file', `${file.name}: ${err.message}`));
    return;
  }
  await openText(text, file.name);
}

function closeFile() {
  doc.active = false;
  doc.info = null;
  motionCache.clear();
  buildSkeleton();
  buildCharacterBones();
  $('bvh-loaded').hidden = true;
  $('export').textContent = 'Export JSON';
  $('export').title = 'Download the pose as JSON';
  history.stack = [];
  history.index = -1;
  controls.target.set(0, 0.85, 0);
  camera.position.set(0.75, 1.3, 2.9);
  controls.update();
}

// Show another frame of the file: its targets go (they were for the other frame), pins stay.
function setFrame(frame) {
  if (!doc.active || frame === doc.frame) return;
  endDrag(false);
  cancelSolves();
  doc.frame = frame;
  doc.shown = doc.text;
  state.targets.clear();
  state.committed = filePose(doc.text, frame);
  state.pose = clonePose(state.committed);
  // not an undo step: the current history entry follows the frame
  if (history.index >= 0) history.stack[history.index] = snapshot();
  refresh();
}

function refreshFrame() {
  if (!doc.active) return;
  $('bvh-frame').value = String(doc.frame);
  const t = doc.frame * doc.info.frame_time;
  $('bvh-frame-label').textContent = `${doc.frame} / ${doc.info.frames - 1} (${t.toFixed(2)} s)`;
}

function wireControls() {
  viewport.addEventListener('pointerdown', onPointerDown, { capture: true });
  window.addEventListener('pointermove', onPointerMove);
  window.addEventListener('pointerup', onPointerUp);
  window.addEventListener('pointercancel', () => endDrag(false));
  renderer.domElement.addEventListener('pointerleave', () => {
    if (!drag) $('hud').hidden = true;
  });
  for (const input of document.querySelectorAll('input[name=method], #exact, #preserve, #tolerance')) {
    input.addEventListener('change', () => requestSolve(true));
  }
  $('sample').addEventListener('change', (ev) => loadSample(Number(ev.target.value)));
  $('bvh-file').addEventListener('change', (ev) => {
    openFile(ev.target.files[0]);
    ev.target.value = ''; // the same file can be opened again
  });
  for (const id of ['bvh-units', 'bvh-up']) {
    $(id).addEventListener('change', () => {
      if (doc.tried) openText(doc.active ? doc.text : doc.tried.text, doc.tried.name);
    });
  }
  $('bvh-frame').addEventListener('input', (ev) => setFrame(Number(ev.target.value)));
  let dragDepth = 0;
  const hasFiles = (ev) => ev.dataTransfer && [...ev.dataTransfer.types].includes('Files');
  window.addEventListener('dragenter', (ev) => {
    if (!hasFiles(ev)) return;
    dragDepth += 1;
    $('drop-hint').hidden = false;
  });
  window.addEventListener('dragleave', () => {
    dragDepth = Math.max(dragDepth - 1, 0);
    if (dragDepth === 0) $('drop-hint').hidden = true;
  });
  window.addEventListener('dragover', (ev) => {
    if (hasFiles(ev)) ev.preventDefault(); // allows the drop
  });
  window.addEventListener('drop', (ev) => {
    ev.preventDefault();
    dragDepth = 0;
    $('drop-hint').hidden = true;
    const file = ev.dataTransfer && ev.dataTransfer.files[0];
    if (file) openFile(file);
  });
  $('undo').addEventListener('click', undo);
  $('redo').addEventListener('click', redo);
  $('reset').addEventListener('click', reset);
  $('clear-targets').addEventListener('click', clearTargets);
  $('export').addEventListener('click', exportPose);
  $('error-close').addEventListener('click', clearError);
  $('connection').addEventListener('submit', (ev) => ev.preventDefault());
  $('api-key').addEventListener('change', () => {
    if (!connected) loadSkeleton();
    requestSolve(false);
  });
  window.addEventListener('keydown', (ev) => {
    if (ev.target instanceof HTMLInputElement && !['checkbox', 'radio', 'range'].includes(ev.target.type)) return;
    const mod = ev.ctrlKey || ev.metaKey;
    if (ev.key === 'Escape') {
      endDrag(false);
    } else if (mod && ev.key.toLowerCase() === 'z') {
      ev.preventDefault();
      if (ev.shiftKey) redo();
      else undo();
    } else if (mod && ev.key.toLowerCase() === 'y') {
      ev.preventDefault();
      redo();
    }
  });
}

// ------------------------------------------------------------------------------------
// Frame loop: render on demand, send at most one solve per frame and one in flight.
// ------------------------------------------------------------------------------------
function frame() {
  if (solver.dirty && !solver.inflight) sendSolve();
  if (needsRender) {
    needsRender = false;
    for (const ring of pinRings.values()) ring.quaternion.copy(camera.quaternion);
    renderer.render(scene, camera);
  }
  requestAnimationFrame(frame);
}

// ------------------------------------------------------------------------------------
// Start-up
// ------------------------------------------------------------------------------------
let ready = false;
let connected = false;
let loadingSkeleton = false;

async function loadSkeleton() {
  if (loadingSkeleton) return;
  loadingSkeleton = true;
  try {
    await fetchSkeleton();
  } finally {
    loadingSkeleton = false;
  }
}

async function fetchSkeleton() {
  for (;;) {
    try {
      const res = await api('GET', 'v1/skeleton');
      const { joints, parents } = res.data;
      const same = joints.length === state.joints.length && joints.every((j) => state.parents[j] === parents[j]);
      if (!same) {
        state.joints = joints;
        state.parents = parents;
        buildSkeleton();
        refresh();
      }
      connected = true;
      $('status').textContent = 'connected';
      if (currentError && currentError.status === 503) clearError();
      return;
    } catch (err) {
      showError(err);
      $('status').textContent = 'server not ready';
      if (err.status !== 503 && err.status !== 0) return;
      await new Promise((r) => setTimeout(r, 2000)); // models still loading / server restarting
    }
  }
}

async function loadSamples() {
  const res = await fetch('static/samples.json', { cache: 'no-cache' });
  if (!res.ok) throw new ApiError(res.status, 'Sample poses missing', `static/samples.json: HTTP ${res.status}`);
  const doc = await res.json();
  return doc.samples;
}

async function main() {
  buildSkeleton();
  resize();
  wireControls();
  requestAnimationFrame(frame);
  try {
    state.samples = await loadSamples();
  } catch (err) {
    showError(err);
    return;
  }
  const select = $('sample');
  state.samples.forEach((s, i) => {
    const opt = document.createElement('option');
    opt.value = String(i);
    opt.textContent = s.name;
    opt.title = `${s.clip}, frame ${s.frame}`;
    select.appendChild(opt);
  });
  loadSample(0);
  ready = true;
  $('status').textContent = 'connecting…';
  loadSkeleton();
}

// Read-only hook for tests and debugging.
window.marionette = Object.freeze({
  ready: () => ready,
  pose: () => (state.pose ? clonePose(state.pose) : null),
  committedPose: () => (state.committed ? clonePose(state.committed) : null),
  lastSolve: () => (solver.last ? structuredClone(solver.last) : null),
  solveCount: () => ({ sent: solver.sent, answered: solver.answered, inflight: solver.inflight, dirty: solver.dirty }),
  targets: () => Object.fromEntries([...state.targets].map(([j, p]) => [j, [...p]])),
  pins: () => [...state.pins],
  options: () => options(),
  error: () => (currentError ? { ...currentError } : null),
  history: () => ({ length: history.stack.length, index: history.index }),
  joints: () => [...state.joints],
  projectJoint: (name) => {
    const p = state.pose && state.pose[name];
    if (!p) return null;
    const s = toScreen(p);
    return { x: s.x, y: s.y };
  },
  projectPoint: (p) => {
    const s = toScreen(p);
    return { x: s.x, y: s.y };
  },
  exportDocument: () => exportDocument(),
  // the open BVH file (null when none): what it is and what is drawn
  bvh: () => (doc.active ? {
    name: doc.name,
    frame: doc.frame,
    frames: doc.info.frames,
    units: doc.info.units,
    up: doc.info.up,
    scheme: doc.info.scheme,
    joints: doc.info.joints.map((j) => j.name),
    edited: doc.text !== doc.original,
  } : null),
  bvhText: () => (doc.active ? doc.text : null),
  // every joint of the file on screen: file units and axes, and page (world) coordinates
  bvhPositions: () => (doc.active ? fileFrame(doc.shown, doc.frame).fk.pos : null),
  bvhWorld: () => (doc.active ? doc.world.map((p) => [...p]) : null),
});

main();
