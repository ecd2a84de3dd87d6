/**
 * The live stream's binary frames (`?encoding=binary`, docs/rest-api.md#live-stream, written
 * by app/runs/frame_encoding.py): a 12-byte header ("MWLF", version 1, the JSON part's
 * length as uint32 little-endian), the JSON part `{frame, arrays}`, then the arrays,
 * little-endian, each at a multiple of 8 bytes from the 8-aligned data block. Decoded into
 * exactly the objects a JSON frame parses to: nested arrays of numbers, NaN as null.
 */

const MAGIC = "MWLF";
const VERSION = 1;
const HEADER_BYTES = 12;
const ALIGN = 8;
const TYPED = { f32: Float32Array, f64: Float64Array };

/** The frame object of one binary message (an ArrayBuffer); throws on another layout. */
export function decodeFrame(buffer) {
  const view = new DataView(buffer);
  const magic = String.fromCharCode(...new Uint8Array(buffer, 0, 4));
  if (magic !== MAGIC || view.getUint8(4) !== VERSION) {
    throw new Error(`not a version ${VERSION} ${MAGIC} frame`);
  }
  const length = view.getUint32(8, true);
  const end = HEADER_BYTES + length;
  const head = JSON.parse(new TextDecoder().decode(new Uint8Array(buffer, HEADER_BYTES, length)));
  const start = end + ((ALIGN - (end % ALIGN)) % ALIGN);
  const frame = head.frame;
  for (const ref of head.arrays) {
    const count = ref.shape.reduce((a, b) => a * b, 1);
    const flat = new TYPED[ref.dtype](buffer, start + ref.offset, count);
    put(frame, ref.path, nested(flat, ref.shape));
  }
  return frame;
}

/** The typed array as nested plain arrays of the given shape, NaN → null (as in JSON). */
function nested(flat, shape, offset = 0, axis = 0) {
  const n = shape[axis];
  if (axis === shape.length - 1) {
    const out = new Array(n);
    for (let i = 0; i < n; i++) {
      const v = flat[offset + i];
      out[i] = Number.isNaN(v) ? null : v;
    }
    return out;
  }
  const stride = shape.slice(axis + 1).reduce((a, b) => a * b, 1);
  return Array.from({ length: n }, (_, i) => nested(flat, shape, offset + i * stride, axis + 1));
}

function put(frame, path, value) {
  let target = frame;
  for (const key of path.slice(0, -1)) target = target[key];
  target[path[path.length - 1]] = value;
}
