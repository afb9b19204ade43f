// A nudge key's world direction and step (no imports: its test runs it in Node).
//
// Along world axes, as seen from the camera: Left / Right along the floor axis (X or Z)
// nearest the screen's right, Up / Down along the other floor axis (Up: away from the viewer),
// PageUp / PageDown along +Y / -Y. An axis, not the screen's own direction, so a nudge
// changes one coordinate by exactly the step (the x / y / z fields show it), and Right
// still moves the target rightwards on the screen (within 45 degrees) wherever the view is
// orbited to.

export const NUDGE_KEYS = ['ArrowLeft', 'ArrowRight', 'ArrowUp', 'ArrowDown', 'PageUp', 'PageDown'];

// ``key``'s direction, [x, y, z] with one component +-1, or null for another key. ``right``:
// the camera's right in the world (level: the view never rolls); ``ahead``: where it looks;
// ``up``: its up, which says "away" when it looks straight down (or up).
export function nudgeDirection(key, right, ahead, up) {
  if (key === 'PageUp') return [0, 1, 0];
  if (key === 'PageDown') return [0, -1, 0];
  if (!NUDGE_KEYS.includes(key)) return null;
  const onX = Math.abs(right[0]) >= Math.abs(right[2]);
  const level = Math.hypot(ahead[0], ahead[2]) < 1e-6 ? up : ahead; // (from above: screen up)
  const r = onX ? [Math.sign(right[0]) || 1, 0, 0] : [0, 0, Math.sign(right[2]) || 1];
  const a = onX ? [0, 0, Math.sign(level[2]) || -1] : [Math.sign(level[0]) || 1, 0, 0];
  const flip = (v) => v.map((c) => (c === 0 ? 0 : -c));
  return { ArrowRight: r, ArrowLeft: flip(r), ArrowUp: a, ArrowDown: flip(a) }[key];
}

// The step of a nudge (m): the base step, Shift 10 times more (coarse), Alt 10 times less
// (fine); both: the base.
export function nudgeStep(base, { shiftKey = false, altKey = false } = {}) {
  if (shiftKey && altKey) return base;
  return shiftKey ? base * 10 : altKey ? base / 10 : base;
}
