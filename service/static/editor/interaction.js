// Pointer interaction: screen-space picking, ray-plane dragging of joints and targets, the
// hover label, pins and target removal. (The keyboard's way: keys.js.)

import * as THREE from 'three';
import { $, doc, pointerDrag, solver, state, ui } from './state.js';
import { cancelSolves, commitShown, requestSolve, restore, snapshot } from './solve.js';
import {
  camera, controls, drawPose, handleRadius, renderer, TARGET_RADIUS, viewport,
} from './scene.js';
import { refresh, refreshPanel } from './panel.js';
import { select } from './keys.js';

const PICK_PIXELS = 18;
const TARGET_PREFERENCE = 2;

// ------------------------------------------------------------------------------------
// Screen-space picking and ray-plane dragging
// ------------------------------------------------------------------------------------
export function toScreen(p) {
  const v = new THREE.Vector3(p[0], p[1], p[2]).project(camera);
  const rect = renderer.domElement.getBoundingClientRect();
  return {
    x: rect.left + ((v.x + 1) / 2) * rect.width,
    y: rect.top + ((1 - v.y) / 2) * rect.height,
    depth: v.z,
  };
}

// What the pointer grabs: the handle (joint or target marker) whose centre is nearest to
// it, with no bias for any joint (the head's took the pointer from the neck even with the
// neck under it, as in a bow); a target beats its own joint where they coincide
// (TARGET_PREFERENCE px). A handle is in reach within PICK_PIXELS of its centre, or anywhere
// on its sphere as drawn (a sample's head is larger), unless another centre is nearer.
function pick(clientX, clientY) {
  let best = null;
  const camUp = new THREE.Vector3(0, 1, 0).applyQuaternion(camera.quaternion);
  const consider = (kind, joint, p, radius) => {
    const s = toScreen(p);
    if (s.depth < -1 || s.depth > 1) return;
    const rim = toScreen([p[0] + camUp.x * radius, p[1] + camUp.y * radius, p[2] + camUp.z * radius]);
    const d = Math.hypot(s.x - clientX, s.y - clientY);
    // (NaN: a frame cut short has no pose; it passed every test, grabbed a press anywhere
    // and the view could not be orbited)
    if (!(d <= Math.max(PICK_PIXELS, Math.hypot(rim.x - s.x, rim.y - s.y)))) return;
    const score = d - (kind === 'target' ? TARGET_PREFERENCE : 0);
    if (!best || score < best.score) best = { kind, joint, score };
  };
  for (const [joint, p] of state.targets) consider('target', joint, p, TARGET_RADIUS);
  for (const joint of state.joints) {
    if (state.pose && state.pose[joint]) consider('joint', joint, state.pose[joint], handleRadius(joint));
  }
  return best;
}

const raycaster = new THREE.Raycaster();

function pointerRay(clientX, clientY) {
  const rect = renderer.domElement.getBoundingClientRect();
  const ndc = new THREE.Vector2(
    ((clientX - rect.left) / rect.width) * 2 - 1,
    -((clientY - rect.top) / rect.height) * 2 + 1,
  );
  raycaster.setFromCamera(ndc, camera);
  return raycaster.ray;
}

export function onPointerDown(ev) {
  if (ev.button !== 0 || !state.pose) return;
  let hit = pick(ev.clientX, ev.clientY);
  if (!hit) return; // empty space: OrbitControls gets the event
  ev.stopPropagation();
  ev.preventDefault();
  if (ui.reading) { // a file being opened or read again: editing waits for it (file.js)
    moveHud(ev.clientX, ev.clientY, `${ui.reading}: editing waits`);
    return;
  }
  // (preventDefault keeps the focus where it was: a panel field typed in would take the
  // keys, Ctrl+Z undoing its text and not the drag). The view takes it instead: the joint
  // pressed is selected, and the keys nudge it next (keys.js).
  const shown = state.pose;
  renderer.domElement.focus({ preventScroll: true });
  // The field left may have shown another pose (a frame typed in the frame box, taken as
  // it loses the focus): what is under the pointer is picked on the pose shown now, or
  // nothing is (the press took the frame). The joint picked on the frame before was
  // grabbed on the new one, away from the pointer, and dragged there: an edit the user
  // never saw, the joint not under the cursor.
  if (state.pose !== shown) {
    camera.updateMatrixWorld(); // (the view followed the character)
    hit = pick(ev.clientX, ev.clientY);
    if (!hit) return;
  }
  if (ui.drag) endDrag(true); // (a nudge burst under way: committed, keys.js)
  const { joint } = hit;
  select(joint);
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
  ui.drag = { joint, plane, offset, moved: false, before: snapshot(), hadTarget: state.targets.has(joint), pointerId: ev.pointerId };
  controls.enabled = false;
  viewport.style.cursor = 'grabbing';
}

export function onPointerMove(ev) {
  pointer = ev.target === renderer.domElement ? { x: ev.clientX, y: ev.clientY } : null;
  if (!pointerDrag()) {
    hoverAt(pointer);
    return;
  }
  const ray = pointerRay(ev.clientX, ev.clientY);
  const hitPoint = new THREE.Vector3();
  if (!ray.intersectPlane(ui.drag.plane, hitPoint)) return;
  hitPoint.add(ui.drag.offset);
  if (!ui.drag.moved) {
    ui.drag.moved = true;
    state.pins.delete(ui.drag.joint); // a dragged joint follows its target, not its pin
  }
  state.targets.set(ui.drag.joint, [hitPoint.x, hitPoint.y, hitPoint.z]);
  requestSolve(false);
  refreshPanel();
  drawPose();
  moveHud(ev.clientX, ev.clientY, ui.drag.joint);
}

export function onPointerUp() {
  if (pointerDrag()) endDrag(true);
}

// End the gesture: commit its last solve, or (cancel) go back to where it started.
export function endDrag(commit) {
  if (!ui.drag) return;
  const d = ui.drag;
  ui.drag = null;
  controls.enabled = true;
  viewport.style.cursor = '';
  if (!d.moved) { // a click, not a drag; its press held back the last gesture's answer:
    if (commit && solver.commitPending) requestSolve(true); // asked again, to commit it
    return;
  }
  if (commit) {
    requestSolve(true);
  } else {
    cancelSolves();
    restore(d.before);
    refresh();
  }
}

// Where the pointer last was over the view (null once it left): the hover label and the
// joint lit are found again there when the pose moves under a still pointer (rehover).
let pointer = null; // (onPointerMove)

function hoverAt(at) {
  camera.updateMatrixWorld(); // (moved since the last render: a frame followed, a file opened)
  const hit = at ? pick(at.x, at.y) : null;
  const name = hit ? hit.joint : null;
  viewport.style.cursor = hit ? (ui.reading ? 'progress' : 'grab') : '';
  if (name !== ui.hovered) {
    ui.hovered = name;
    drawPose();
  }
  if (hit) moveHud(at.x, at.y, hit.kind === 'target' ? `target: ${name}` : name);
  else $('hud').hidden = true;
}

// The pose, targets or file changed under a still pointer (another frame, an undo, a file
// opened, an answer): the label and the joint lit are those under it now. They stayed the
// joint's that was there, over empty space (its label the file's before: "left_wrist
// (LeftHand)" over another file's body).
export function rehover() {
  if (!ui.drag) hoverAt(pointer);
}

// The pointer left the view: no label (a drag's stays, at the pointer).
export function pointerLeft() {
  pointer = null;
  if (!ui.drag) $('hud').hidden = true;
}

function moveHud(x, y, text) {
  const hud = $('hud');
  const anchor = doc.active && doc.info.anchors[text];
  hud.textContent = anchor ? `${text} (${anchor.label})` : text;
  hud.style.left = `${x + 14}px`;
  hud.style.top = `${y + 10}px`;
  hud.hidden = false;
}

export function togglePin(joint) {
  if (ui.reading) return; // (editing waits for a file's answer)
  if (state.pins.has(joint)) {
    state.pins.delete(joint);
  } else {
    state.pins.add(joint);
    if (state.targets.delete(joint)) {
      // It was targeted: it now stays where the last solve put it (an answer still on its
      // way, for the targets before, is dropped: drawn, it was never committed)
      cancelSolves();
      commitShown();
    }
  }
  requestSolve(true);
  refresh();
}

export function removeTarget(joint) {
  if (ui.reading) return;
  state.targets.delete(joint);
  cancelSolves(); // (as clearTargets: a late answer for the targets before is not drawn)
  commitShown();
  requestSolve(true);
  refresh();
}

export function clearTargets() {
  if (ui.reading || state.targets.size === 0) return;
  cancelSolves();
  state.targets.clear();
  commitShown();
  requestSolve(true);
}
