// Arrays on the stream: msgpack maps {shape, dtype, data} of C-order little-endian raw bytes.
import { DataUtils } from "three";

function aligned(bytes) {
  // msgpack bin values are views into the message; typed arrays need their own aligned buffer
  return bytes.buffer.slice(bytes.byteOffset, bytes.byteOffset + bytes.byteLength);
}

export function decodeArray(a) {
  const { dtype, shape, data } = a;
  let values;
  if (dtype === "<f4") values = new Float32Array(aligned(data));
  else if (dtype === "<f8") values = Float32Array.from(new Float64Array(aligned(data)));
  else if (dtype === "<i4") values = new Int32Array(aligned(data));
  else if (dtype === "<i8") values = Int32Array.from(new BigInt64Array(aligned(data)), Number);
  else if (dtype === "<f2") {
    const half = new Uint16Array(aligned(data));
    values = new Float32Array(half.length);
    for (let i = 0; i < half.length; i++) values[i] = DataUtils.fromHalfFloat(half[i]);
  } else if (dtype === "|u1") values = new Uint8Array(aligned(data));
  else throw new Error(`unsupported array dtype ${dtype}`);
  return { shape, values };
}
