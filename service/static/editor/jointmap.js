// A joint map for a BVH file whose joint names the service's automatic map cannot resolve:
// JSON {canonical joint: the file's joint name} in the panel's text field, sent as
// `joint_map` with every v1/bvh/inspect and v1/bvh/solve of the file it was given for
// (file.js). A refusal naming unmapped joints opens the field with a template of them and
// lists the file's joints as the service names them (fileJoints).

import { $ } from './state.js';
import { ApiError } from './api.js';
import { fileJoints } from './bvhnames.js';

const SHAPE = 'give a JSON object {"canonical joint": "the file\'s joint name"}';

// The map in the field: null when it is empty (or all its names are blank, left out);
// refused (ApiError) when it is not a JSON object of strings.
export function readMap() {
  const raw = $('bvh-map').value.trim();
  if (!raw) return null;
  let value;
  try {
    value = JSON.parse(raw);
  } catch (err) {
    throw new ApiError(-1, 'Joint map', `not JSON (${err.message}): ${SHAPE}`);
  }
  if (value === null || typeof value !== 'object' || Array.isArray(value)) {
    throw new ApiError(-1, 'Joint map', SHAPE);
  }
  const map = {};
  for (const [joint, name] of Object.entries(value)) {
    if (typeof name !== 'string') {
      const given = JSON.stringify(name);
      throw new ApiError(-1, 'Joint map', `${joint}: give the file's joint name as a string, not ${given}`);
    }
    if (name.trim()) map[joint] = name;
  }
  return Object.keys(map).length ? map : null;
}

// The field shows ``map`` (the map a file is read with; null: empty).
export function showMap(map) {
  $('bvh-map').value = map ? JSON.stringify(map, null, 2) : '';
  $('bvh-map-joints').hidden = true;
  if (map) $('bvh-map-box').open = true;
}

// A refusal of ``text`` that names the canonical joints no joint was found for: the field
// opens with them added (blank, to fill in) to what it holds, and the file's joints listed.
export function offerTemplate(err, text) {
  if (!(err instanceof ApiError) || err.status !== 422) return;
  const found = /no joint found for \[([^\]]*)\]/.exec(err.detail);
  if (!found) return;
  let map = {};
  try {
    const raw = $('bvh-map').value.trim();
    map = raw ? JSON.parse(raw) : {};
  } catch {
    return; // the user's text, unreadable: left as it is
  }
  if (map === null || typeof map !== 'object' || Array.isArray(map)) return;
  for (const [, joint] of found[1].matchAll(/'([^']*)'/g)) {
    if (!map[joint]) map[joint] = '';
  }
  $('bvh-map').value = JSON.stringify(map, null, 2);
  const joints = fileJoints(text);
  const quoted = joints.slice(0, 300).map((name) => JSON.stringify(name)); // (a tab: \t)
  const shown = quoted.join(', ') + (joints.length > 300 ? ', …' : '');
  $('bvh-map-joints').textContent = `The file's joints: ${shown}`;
  $('bvh-map-joints').hidden = false;
  $('bvh-map-box').open = true;
}
