"""Writes small synthetic RGL measurements (tensor files) as seeds of the rgl_reader fuzz target:
an isotropic one with and without the Jacobian flag, and an anisotropic one over a half circle of
azimuths. They parse and evaluate, so byte mutations start from files that reach the
interpolants. Standard library only; run by seed.sh (the outputs are committed)."""

import math
import struct
import sys
from pathlib import Path

# dtype codes of Mitsuba's tensor files
UINT8, FLOAT32 = 1, 10


def tensor_file(fields):
    """``fields``: (name, dtype, shape, bytes); the layout of nbrdf_core::rgl::tensor."""
    header_len = 12 + 2 + 4 + sum(2 + len(n) + 2 + 1 + 8 + 8 * len(s) for n, _, s, _ in fields)
    offset = (header_len + 7) // 8 * 8
    header = bytearray(b"tensor_file\0" + bytes([1, 0]) + struct.pack("<I", len(fields)))
    data = bytearray()
    for name, dtype, shape, payload in fields:
        header += struct.pack("<H", len(name)) + name.encode()
        header += struct.pack("<HBQ", len(shape), dtype, offset + len(data))
        header += b"".join(struct.pack("<Q", n) for n in shape)
        data += payload + bytes(-len(payload) % 8)
    return bytes(header) + bytes(offset - len(header)) + bytes(data)


def floats(values):
    return struct.pack(f"<{len(values)}f", *values)


def measurement(n_phi, phi_span, n_theta, res, jacobian):
    theta = [0.5 * math.pi * i / (n_theta - 1) for i in range(n_theta)]
    phi = [phi_span * i / max(n_phi - 1, 1) for i in range(n_phi)]
    cells = n_phi * n_theta * res * res
    vndf = [1.0 + (k % 7) for k in range(cells)]
    rgb = [0.05 + 0.9 * ((k * 37) % 11) / 11 for k in range(3 * cells)]
    return tensor_file(
        [
            ("description", UINT8, [9], b"synthetic"),
            ("phi_i", FLOAT32, [n_phi], floats(phi)),
            ("theta_i", FLOAT32, [n_theta], floats(theta)),
            ("sigma", FLOAT32, [2, 8], floats([0.75 + 0.01 * k for k in range(16)])),
            ("ndf", FLOAT32, [2, 8], floats([3.0 - 0.1 * k for k in range(16)])),
            ("vndf", FLOAT32, [n_phi, n_theta, res, res], floats(vndf)),
            ("luminance", FLOAT32, [n_phi, n_theta, res, res], floats([1.0] * cells)),
            ("rgb", FLOAT32, [n_phi, n_theta, 3, res, res], floats(rgb)),
            ("jacobian", UINT8, [1], bytes([jacobian])),
        ]
    )


def main(out: Path):
    out.mkdir(parents=True, exist_ok=True)
    seeds = {
        "seed-isotropic-jacobian.bsdf": measurement(1, 0.0, 4, 6, 1),
        "seed-isotropic-plain.bsdf": measurement(1, 0.0, 3, 4, 0),
        "seed-anisotropic-half.bsdf": measurement(3, math.pi, 3, 4, 1),
    }
    for name, data in seeds.items():
        (out / name).write_bytes(data)


if __name__ == "__main__":
    main(Path(sys.argv[1]))
