// The editor's shared state: the skeleton, the pose and its edits, the solver's bookkeeping,
// the open BVH file, the undo history, and `ui` (the few flags several modules read and
// write). Every module imports these objects; none keeps a copy.

import * as THREE from 'three';

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

export const $ = (id) => document.getElementById(id);

// ------------------------------------------------------------------------------------
// State
// ------------------------------------------------------------------------------------
export const state = {
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

export const solver = {
  dirty: false, // an edit is waiting to be solved
  inflight: false,
  epoch: 0, // bumped by undo/redo/reset/sample: answers of older epochs are dropped
  commitPending: false, // commit the answer to the latest edit (end of a gesture)
  afterCommit: [], // what waits for that commit: a scrub, an export, a units change
  giveUp: null, // the AbortController of the solve in flight (cancelSolves gives it up)
  holdUntil: 0, // performance.now() before which no solve is sent (a Retry-After; solve.js)
  busyTries: 0, // a gesture's last solve refused by a busy server, so many times in a row (solve.js)
  interrupted: null, // a gesture's last solve that found no server: {epoch, step, replace} (solve.js)
  again: null, // that edit, being sent again now the server is back (solve.js)
  sent: 0,
  answered: 0,
  last: null,
  latencies: [],
};

// The open BVH file (doc.active). doc.text is the committed file (solves start from it),
// doc.shown the file whose frame is on screen (the latest answer during a gesture).
export const doc = {
  active: false,
  name: '',
  original: '', // as opened (Reset)
  text: '',
  shown: '',
  info: null, // the v1/bvh/inspect answer: joints, anchors, units, up, frames, ...
  frame: 0,
  toWorld: new THREE.Matrix4(),
  fromWorld: new THREE.Matrix4(),
  // {text, name, encoding, jointMap, yes, settings} of the last file opened (re-opened when
  // units / up change; yes: file.js replaceable; settings: the menus it was sent with)
  tried: null,
  jointMap: null, // the open file's joint map ({canonical: the file's joint name}) or null: sent with its solves
  encoding: 'utf-8', // of the open file's bytes: 'utf-8', 'latin-1', 'utf-16le' or 'utf-16be' (written back the same)
  drawn: { row: null }, // the frame's values the character's bones show (scene.js)
  world: [], // world positions of every joint of the file, as drawn
  followed: null, // {frame, pelvis}: where the view last followed the character to (file.js)
};

// The undo history (history.js): its steps, the one shown, and the open file's text as that
// step has it (a step holds only how its text differs from the step before).
export const history = { stack: [], index: -1, text: null };

// Flags several modules read and write (an importer cannot assign a module's `let`).
export const ui = {
  currentError: null, // the error on the banner (api.js), or null
  errorOwner: null, // a failed solve's banner: {step, pending, lasting}, the edit it belongs to (solve.js)
  hovered: null, // the joint (or target) under the pointer
  needsRender: true, // the frame loop renders when set
  drag: null, // the gesture in progress (interaction.js; a nudge burst's, keys.js), or null
  selected: null, // the joint selected for the keys and the panel's fields (keys.js), or null
  connected: false, // GET v1/skeleton has answered
  reading: null, // a file being opened or read again (file.js): editing waits for its answer
};

// The gesture in progress is the mouse's (a drag: interaction.js), not a nudge burst's (keys.js:
// ui.drag with `keys`, no plane, ended with its keys): the pointer's handlers move and end
// only a drag, and the keys begin no burst during one.
export const pointerDrag = () => Boolean(ui.drag) && !ui.drag.keys;
