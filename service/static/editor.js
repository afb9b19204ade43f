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
// the frame slider (or the frame box) scrubs; Export downloads the edited file. The page's world is the file's
// mapped to metres, +Y up, the character (as opened) facing +Z on the grid.
//
// Tests read the page through `window.marionette` (read-only).
//
// Modules (static/editor/): state.js (shared state), api.js (requests, error banner),
// solve.js (edits, undo, solving), history.js (the undo history's steps), scene.js (three.js
// drawing), interaction.js (picking, dragging, pins), keys.js (a joint edited from the
// keyboard and the panel's fields), panel.js (side panel, export), file.js (BVH files),
// jointmap.js (a file's joint map). This entry module wires the controls, runs
// the frame loop, starts up and sets the test hook.

import { $, doc, history, pointerDrag, solver, state, ui } from './editor/state.js';
import { api, ApiError, clearError, onBack, showError } from './editor/api.js';
import {
  BOUNDED, checkField, chooseSample, clonePose, loadSample, options, redo, requestSolve, reset,
  sendSolve, setUpFields, takeField, undo,
} from './editor/solve.js';
import {
  buildSkeleton, camera, floorCentre, followRatio, pinRings, renderer, resize, scene, selectionRing,
  viewport,
} from './editor/scene.js';
import {
  clearTargets, endDrag, onPointerDown, onPointerMove, onPointerUp, pointerLeft, toScreen,
} from './editor/interaction.js';
import { exportDocument, exportPose, refresh, titleMenu } from './editor/panel.js';
import {
  fileFrame, hasEdits, jumpToFrame, openFile, otherUnits, readAgain, setFrame,
} from './editor/file.js';
import { heldSize } from './editor/history.js';
import { knowLimit } from './editor/inspect.js';
import { wireKeys } from './editor/keys.js';

// ------------------------------------------------------------------------------------
// Wiring: pointer, keyboard, panel controls, file picker and drop
// ------------------------------------------------------------------------------------
function wireControls() {
  viewport.addEventListener('pointerdown', onPointerDown, { capture: true });
  window.addEventListener('pointermove', onPointerMove);
  window.addEventListener('pointerup', onPointerUp);
  window.addEventListener('pointercancel', () => {
    if (pointerDrag()) endDrag(false);
  });
  renderer.domElement.addEventListener('pointerleave', pointerLeft);
  for (const input of document.querySelectorAll('input[name=method], #exact, #preserve, #turn-search')) {
    input.addEventListener('change', () => requestSolve(true));
  }
  // checked in the page (solve.js, checkField): as typed, marked or cleared at once; left
  // (or Enter), a value in range re-solves, one out of it is refused and nothing is sent
  for (const id of BOUNDED) {
    $(id).addEventListener('input', () => checkField(id, { typing: true }));
    $(id).addEventListener('change', () => {
      if (takeField(id)) requestSolve(true);
    });
  }
  $('carry').addEventListener('change', (ev) => {
    ev.target.dataset.touched = '1';
    $('carry-label').textContent = ev.target.valueAsNumber.toFixed(2);
    requestSolve(true);
  });
  // a menu's tooltip names the choice shown, whole (panel.js titleMenu), arrowed to or picked
  for (const menu of document.querySelectorAll('#panel select')) {
    for (const type of ['input', 'change']) menu.addEventListener(type, () => titleMenu(menu));
  }
  // (arrowed through: taken on Enter, as the file's menus below; left, the menu goes back:
  // a sample replaces the file open. Each arrow loaded its sample, the first closing the
  // file, unasked where it had no edits, no undo bringing it back)
  chosen($('sample'), (menu, how, from) => {
    if (how === 'left') menu.value = from;
    else chooseSample(Number(menu.value));
  });
  // a button, not a label for the hidden input: a label takes no focus, and no Tab reached it
  $('bvh-open').addEventListener('click', () => $('bvh-file').click());
  $('bvh-file').addEventListener('change', (ev) => {
    openFile(ev.target.files[0]);
    ev.target.value = ''; // the same file can be opened again
  });
  // Units, up or the joint map changed: read again the file last asked for (file.js).
  for (const id of ['bvh-up', 'bvh-root']) chosen($(id), readAgain);
  chosen($('bvh-units'), (menu, how, from) => {
    if (menu.value !== 'other') readAgain();
    else if (how === 'left') menu.value = from; // (no prompt as the focus goes)
    else if (otherUnits(from)) readAgain(); // (other…: asked first)
  });
  $('bvh-map-apply').addEventListener('click', readAgain);
  $('bvh-map-clear').addEventListener('click', () => {
    $('bvh-map').value = '';
    $('bvh-map-joints').hidden = true;
  });
  $('bvh-frame').addEventListener('input', (ev) => setFrame(Number(ev.target.value)));
  // The frame box: typed, then Enter (or leaving it): that frame; Escape: back; arrows: +-1.
  const box = $('bvh-frame-number');
  box.addEventListener('input', () => { box.dataset.editing = '1'; });
  box.addEventListener('change', () => {
    if (box.dataset.editing) jumpToFrame(box.value);
  });
  box.addEventListener('keydown', (ev) => {
    const key = ev.key.toLowerCase();
    if ((ev.ctrlKey || ev.metaKey) && (key === 'z' || key === 'y')) {
      // Ctrl+Z here is the page's undo (a frame typed is no edit), or, while a frame is
      // being typed, the typing undone: the browser's own undo put back the text typed
      // before, a frame not shown, which the box then jumped to when left.
      ev.preventDefault();
      if (box.dataset.editing) jumpToFrame('');
      else if (key === 'y' || ev.shiftKey) redo();
      else undo();
    } else if (ev.key === 'Enter') {
      ev.preventDefault();
      jumpToFrame(box.value);
    } else if (ev.key === 'Escape') {
      jumpToFrame('');
    } else if (ev.key === 'ArrowUp' || ev.key === 'ArrowDown') {
      ev.preventDefault();
      const next = Number($('bvh-frame').value) + (ev.key === 'ArrowUp' ? 1 : -1);
      if (next >= 0 && next <= Number(box.max)) setFrame(next);
    }
  });
  box.addEventListener('blur', () => {
    if (box.dataset.editing) jumpToFrame(box.value);
  });
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
    if (!ui.connected) loadSkeleton();
    requestSolve(false);
  });
  // Closing or reloading the page with work on it (a file's edits, pins, targets; a
  // sample's) asks, as every other way of dropping it does (file.js hasEdits); it went
  // without a word.
  window.addEventListener('beforeunload', (ev) => {
    if (!hasEdits()) return;
    ev.preventDefault();
    ev.returnValue = ''; // (older browsers ask only when it is set)
  });
  window.addEventListener('keydown', (ev) => {
    if (ev.target instanceof HTMLTextAreaElement) return; // the joint map: its own keys
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

// A menu (a file's units, up, root; the Sample pose) chosen: ``take(menu, how, from)``, ``from`` the value it
// had before. Arrowed through from the keyboard (a closed menu changes, and says so, at each
// arrow or letter), the choice is taken on Enter or when the menu is left, and only if it
// differs from the value before the arrows (``how``: 'enter' or 'left'; a mouse's or a
// picker's choice at once, null): each option passed read the file again, and "other…"
// reached popped its prompt.
const MENU_KEYS = new Set(['ArrowUp', 'ArrowDown', 'ArrowLeft', 'ArrowRight', 'Home', 'End', 'PageUp', 'PageDown']);

function chosen(menu, take) {
  let keyed = false;
  let from = null; // the value before the arrows, while a keyed choice waits
  let last = menu.value; // the value the last choice left (a cancelled other… goes back to it)
  const taken = (how, was) => {
    take(menu, how, was);
    last = menu.value;
  };
  const settle = (how) => {
    const was = from;
    from = null;
    if (menu.value !== was) taken(how, was);
  };
  menu.addEventListener('keydown', (ev) => {
    const mod = ev.altKey || ev.ctrlKey || ev.metaKey;
    if (ev.key === 'Enter' && from !== null) {
      ev.preventDefault();
      keyed = false;
      settle('enter');
      return;
    }
    keyed = !mod && (MENU_KEYS.has(ev.key) || (ev.key.length === 1 && ev.key !== ' '));
    if (keyed && from === null) from = menu.value;
  });
  const seen = () => { last = menu.value; }; // (a value set by the page since: a Sample's reset)
  menu.addEventListener('focus', seen);
  menu.addEventListener('pointerdown', () => { keyed = false; seen(); });
  menu.addEventListener('change', () => {
    if (keyed) return; // (waits: Enter, or the menu left)
    from = null;
    taken(null, last);
  });
  menu.addEventListener('blur', () => {
    keyed = false; // (a change after it, with no key or pointer first, is taken at once)
    if (from !== null) settle('left');
  });
}

// ------------------------------------------------------------------------------------
// Frame loop: render on demand, send at most one solve per frame and one in flight.
// ------------------------------------------------------------------------------------
function frame() {
  followRatio();
  if (solver.dirty && !solver.inflight && performance.now() >= solver.holdUntil) sendSolve();
  if (ui.needsRender) {
    ui.needsRender = false;
    for (const ring of [...pinRings.values(), selectionRing]) ring.quaternion.copy(camera.quaternion);
    renderer.render(scene, camera);
  }
  requestAnimationFrame(frame);
}

// ------------------------------------------------------------------------------------
// Start-up
// ------------------------------------------------------------------------------------
let ready = false;
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
      // connected once the models answer too: the skeleton answers while they load, and
      // the status went "connected", then "server not ready" at the models' 503, each retry
      await showModelDefaults();
      ui.connected = true;
      $('status').textContent = 'connected';
      // (a 503's, the models loading; a 401's, the key now typed: it stayed, stale)
      if (ui.currentError && [401, 503].includes(ui.currentError.status)) clearError();
      return;
    } catch (err) {
      showError(err);
      if (err.status === 401) { // the key's field is shown (api.js), and takes the keys
        $('status').textContent = 'API key needed';
        $('api-key').focus();
        return;
      }
      $('status').textContent = 'server not ready';
      if (err.status !== 503 && err.status !== 0) return;
      await new Promise((r) => setTimeout(r, 2000)); // models still loading / server restarting
    }
  }
}

// The slider starts at the models' own carry (it is sent only once moved); the server's body
// limit is the one a big file is sent a frame at a time over (inspect.js knowLimit).
async function showModelDefaults() {
  const res = await api('GET', 'v1/models');
  knowLimit(res.data.max_body_bytes);
  const slider = $('carry');
  if (!slider.dataset.touched && typeof res.data.carry === 'number') {
    slider.value = String(res.data.carry);
    $('carry-label').textContent = `${res.data.carry.toFixed(2)} (models' default)`;
  }
}

// The server found back after an outage (api.js onBack: restarted, perhaps with other models
// or settings): GET v1/models read again, once, and applied as at start-up
// (showModelDefaults: the carry slider's default where it was not moved, the body limit).
// It was read at start-up only: the slider kept the first server's default, and a file over
// a lower limit went whole to be refused first. A server back but still loading its models
// answers 503 with Retry-After: asked again then (start-up asks every 2 s); models that
// failed to load (no Retry-After), or any other failure: left (the solves say what they
// meet; the banner is theirs). A server gone again: read again once it is back again.
let rereading = false;

async function readModelsAgain() {
  if (!ui.connected || loadingSkeleton || rereading) return; // (start-up reads them)
  rereading = true;
  try {
    for (;;) {
      try {
        await showModelDefaults();
        return;
      } catch (err) {
        if (err.status !== 503 || !err.retryAfter) return;
        await new Promise((r) => setTimeout(r, err.retryAfter * 1000));
      }
    }
  } finally {
    rereading = false;
  }
}
onBack(readModelsAgain);

async function loadSamples() {
  const res = await fetch('static/samples.json', { cache: 'no-cache' });
  if (!res.ok) throw new ApiError(res.status, 'Sample poses missing', `static/samples.json: HTTP ${res.status}`);
  const doc = await res.json();
  return doc.samples;
}

async function main() {
  buildSkeleton();
  resize();
  setUpFields();
  wireControls();
  wireKeys();
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
  selected: () => ui.selected, // the joint the keys and the panel's fields edit (keys.js)
  options: () => options(),
  error: () => (ui.currentError ? { ...ui.currentError } : null),
  history: () => ({ length: history.stack.length, index: history.index }),
  // what the undo history holds: its steps, the characters of their files' changes, and the
  // length of the text shown (held once)
  historySize: () => heldSize(),
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
  floor: () => floorCentre(), // the floor grid's centre (world): under the character shown
  // the open BVH file (null when none): what it is and what is drawn
  bvh: () => (doc.active ? {
    name: doc.name,
    frame: doc.frame,
    frames: doc.info.frames,
    units: doc.info.units,
    up: doc.info.up,
    root: doc.settings.root,
    scheme: doc.info.scheme,
    joints: doc.info.joints.map((j) => j.name),
    edited: doc.text !== doc.original,
    jointMap: doc.jointMap ? { ...doc.jointMap } : null,
  } : null),
  bvhText: () => (doc.active ? doc.text : null),
  // every joint of the file on screen: file units and axes, and page (world) coordinates
  bvhPositions: () => (doc.active ? fileFrame(doc.shown, doc.frame).fk.pos : null),
  bvhWorld: () => (doc.active ? doc.world.map((p) => [...p]) : null),
});

main();
