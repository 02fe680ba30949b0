#!/usr/bin/env python3
"""make_corpus.py: writes the hand-made fuzz seeds into tests/fuzz/corpus/<target>/.

    python3 tests/fuzz/make_corpus.py        (from the repository root)

Every seed is a small valid input, except those named bad_*, which each target must reject.
Two kinds of seed are made by splatd itself and kept as they are (this script leaves them): the
frame target's jpeg_* (see frame_seeds) and the cache target's, which are prep caches of small
clouds (`splatd prep FILE --cache DIR`: 30 and 64 points of xyz, 40 of PLY with colours), valid
ones named after their cloud, damaged ones bad_*; and the splod target's, LOD caches built by
lod_open_cloud with grid_bits 2 and leaf_max 64 (fuzz_one_splod's options; k 24, one thread) of
200 points on a sphere and 400 on a plane (xyz) and 600 on a sphere with colours (PLY), several
levels each; bad_magic, bad_truncated (200 bytes cut) and bad_table (node 1's parent made 5).
build/tools/cache_seeds tests/fuzz/corpus remakes both kinds (after a cache format changes).
tests/test_fuzz_regress.c checks both: valid seeds give 0, bad_* seeds a negative code.
The layouts follow the readers' and protocol/proto.h's descriptions of the formats.
"""
import os
import struct
import sys

ROOT = os.path.join(os.path.dirname(os.path.abspath(__file__)), "corpus")


def put(target, name, data):
    d = os.path.join(ROOT, target)
    os.makedirs(d, exist_ok=True)
    if isinstance(data, str):
        data = data.encode()
    with open(os.path.join(d, name), "wb") as f:
        f.write(data)


# ---------------------------------------------------------------- protocol

MAGIC = 0x544C5053
T = dict(HELLO=1, LIST=2, OPEN=3, CAMERA=4, PARAMS=5, RENDER=6, STREAM=7, PING=8, BYE=9,
         WELCOME=129, CLOUDS=130, INFO=131, PROGRESS=132, FRAME=133, PONG=134, ERROR=135, OK=136)


def msg(t, payload=b"", seq=1, ver=1):
    return struct.pack("<IHHII", MAGIC, ver, T[t], seq, len(payload)) + payload


def s8(s):
    b = s.encode()
    return bytes([len(b)]) + b


def hello(proof=b""):
    return struct.pack("<HH", 1, 1) + s8("splat 0.1") + bytes([len(proof)]) + proof


def camera(w=64, h=48):
    return struct.pack("<9d3f2I", 0, 0, 5, 0, 0, 0, 0, 1, 0, 45.0, 0.0, 0.0, w, h)


def params_payload():
    recs = [("pipeline", 1, struct.pack("<I", 0)), ("splat_scale", 2, struct.pack("<f", 1.5)),
            ("point_budget", 3, struct.pack("<Q", 100000)),
            ("light", 4, struct.pack("<3f", 0.0, 0.5, 1.0)), ("format", 1, struct.pack("<I", 1))]
    b = struct.pack("<H", len(recs))
    for n, t, v in recs:
        b += s8(n) + bytes([t]) + v
    return b


def c2s_session():
    seq = iter(range(1, 100))
    return b"".join([
        msg("HELLO", hello(), next(seq)), msg("LIST", b"", next(seq)),
        msg("OPEN", s8("bun000.ply"), next(seq)), msg("CAMERA", camera(), next(seq)),
        msg("PARAMS", params_payload(), next(seq)), msg("STREAM", struct.pack("<Bf", 1, 30.0), next(seq)),
        msg("RENDER", b"", next(seq)), msg("PING", struct.pack("<Q", 123456789), next(seq)),
        msg("BYE", b"", next(seq))])


def welcome():
    return (struct.pack("<HBB", 1, 1, 0) + bytes(range(32)) + struct.pack("<3I", 65536, 4096, 4096)
            + s8("splatd 0.1") + s8("osmesa") + s8("llvmpipe (LLVM 15.0.6, 256 bits)"))


def clouds():
    items = [("bun000.ply", 1988159, 40256, 1), ("autzen_trim.las", 3742038, 0, 3)]
    b = struct.pack("<I", len(items))
    for n, by, pts, fl in items:
        b += s8(n) + struct.pack("<QQI", by, pts, fl)
    return b


def info():
    return (s8("bun000.ply") + struct.pack("<QQ", 40256, 0)
            + struct.pack("<9d", -0.09, 0.03, -0.06, 0.06, 0.18, 0.06, -0.015, 0.105, 0.0)
            + struct.pack("<IfI", 3, 0.0005, 16) + s8("PLY binary_little_endian 1.0")
            + struct.pack("<12d", 0, 1, 0, -0.17, -0.5, -0.85,  # view: up, dir
                          -0.09, 0.03, -0.06, 0.06, 0.18, 0.06)  # and the box it frames
            + struct.pack("<B6d", 2, -0.09, 0.03, 0.0, 0.06, 0.18, 0.05))  # two hull points


def frame(fmt, w, h, data):
    return struct.pack("<IBBHII4Q", 7, 1, fmt, 0, w, h, 1200, 300, 450, 40256) + data


def s2c_session():
    return b"".join([
        msg("WELCOME", welcome(), 1), msg("CLOUDS", clouds(), 2), msg("INFO", info(), 3),
        msg("PROGRESS", struct.pack("<Bf", 1, 0.41) + s8("kNN 41%"), 3),
        msg("FRAME", frame(3, 2, 2, bytes(range(16))), 4),
        msg("FRAME", frame(0, 64, 48, b"\xff\xd8\xff\xe0jpeg-ish"), 5),
        msg("PONG", struct.pack("<QQ", 123456789, 987654321), 6),
        msg("ERROR", struct.pack("<IH", 10, 13) + b"no such cloud", 7), msg("OK", b"", 8)])


def proto():
    put("proto", "c2s_session", bytes([0x01]) + c2s_session())
    put("proto", "c2s_session_chunk50", bytes([0xE1]) + c2s_session())
    put("proto", "s2c_session", bytes([0x12]) + s2c_session())
    put("proto", "s2c_session_chunk22", bytes([0x72]) + s2c_session())
    put("proto", "preauth_hello_proof", bytes([0x05]) + msg("HELLO", hello(bytes(range(32, 64)))))
    put("proto", "either_dir", bytes([0x28]) + msg("PING", struct.pack("<Q", 1))
        + msg("PONG", struct.pack("<QQ", 1, 2)))
    put("proto", "bad_magic", bytes([0x01]) + b"GET / HTTP/1.1\r\n\r\n")
    put("proto", "bad_preauth_list", bytes([0x05]) + msg("LIST"))
    put("proto", "bad_camera_eye_is_target",
        bytes([0x01]) + msg("CAMERA", struct.pack("<9d3f2I", 1, 1, 1, 1, 1, 1, 0, 1, 0, 45, 0, 0,
                                                  8, 8)))
    put("proto", "bad_open_dotdot", bytes([0x01]) + msg("OPEN", s8("..")))
    put("proto", "bad_clouds_count", bytes([0x02]) + msg("CLOUDS", struct.pack("<I", 1000000)))


# ---------------------------------------------------------------- PLY

def ply():
    verts = [(0.0, 0.0, 0.0), (1.0, 0.0, 0.5), (0.0, 1.0, -0.25), (1.0, 1.0, 2.0)]
    a = ("ply\nformat ascii 1.0\ncomment made by make_corpus.py\nelement vertex 4\n"
         "property float x\nproperty float y\nproperty float z\nproperty uchar red\n"
         "property uchar green\nproperty uchar blue\nproperty float nx\nproperty float ny\n"
         "property float nz\nelement face 2\nproperty list uchar int vertex_indices\nend_header\n")
    for i, (x, y, z) in enumerate(verts):
        a += "%g %g %g %d %d %d 0 0 1\n" % (x, y, z, 60 * i, 255 - 60 * i, 7)
    a += "3 0 1 2\n3 1 3 2\n"
    put("ply", "ascii_rgb_normal_faces.ply", a)

    h = ("ply\nformat binary_little_endian 1.0\nelement vertex 4\nproperty float x\n"
         "property float y\nproperty float z\nproperty uchar red\nproperty uchar green\n"
         "property uchar blue\nproperty uchar alpha\nproperty float quality\nend_header\n")
    b = h.encode()
    for i, (x, y, z) in enumerate(verts):
        b += struct.pack("<3f4Bf", x, y, z, 10 * i, 20 * i, 30 * i, 255, 0.25 * i)
    put("ply", "binary_le_rgba_quality.ply", b)

    h = ("ply\nformat binary_big_endian 1.0\nelement face 1\n"
         "property list uchar uint vertex_indices\nelement vertex 4\nproperty double x\n"
         "property double y\nproperty double z\nproperty ushort intensity\nproperty float radius\n"
         "property short red\nproperty short green\nproperty short blue\nend_header\n")
    b = h.encode() + struct.pack(">B3I", 3, 0, 1, 2)
    for i, (x, y, z) in enumerate(verts):
        b += struct.pack(">3dHf3h", x, y, z, 1000 * i, 0.01, 0, 30000, 65535 // 2)
    put("ply", "binary_be_face_first_intensity_radius.ply", b)

    put("ply", "bad_empty.ply", b"")
    put("ply", "bad_truncated.ply", "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\n"
        "property float y\nproperty float z\nend_header\n0 0 0\n1 1 1\n")
    put("ply", "bad_no_z.ply", "ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\n"
        "property float y\nend_header\n0 0\n")


# ---------------------------------------------------------------- PCD

def lzf_compress(data):
    """A small greedy LZF compressor (literal runs and back references up to 8 KiB back)."""
    out, lit, i, n = bytearray(), bytearray(), 0, len(data)

    def flush():
        nonlocal lit
        while lit:
            chunk, lit = lit[:32], lit[32:]
            out.append(len(chunk) - 1)
            out.extend(chunk)

    while i < n:
        best_len, best_dist = 0, 0
        for j in range(max(0, i - 8192), i):
            k = 0
            while i + k < n and k < 264 and data[j + k] == data[i + k]:
                k += 1
            if k > best_len:
                best_len, best_dist = k, i - j
        if best_len >= 3:
            flush()
            ln, d = best_len - 2, best_dist - 1
            if ln < 7:
                out.append((ln << 5) | (d >> 8))
            else:
                out.append((7 << 5) | (d >> 8))
                out.append(ln - 7)
            out.append(d & 0xFF)
            i += best_len
        else:
            lit.append(data[i])
            i += 1
    flush()
    return bytes(out)


def pcd_header(fields, size, typ, count, n, data):
    return ("# .PCD v0.7 - Point Cloud Data file format\nVERSION 0.7\nFIELDS %s\nSIZE %s\n"
            "TYPE %s\nCOUNT %s\nWIDTH %d\nHEIGHT 1\nVIEWPOINT 0 0 0 1 0 0 0\nPOINTS %d\nDATA %s\n"
            % (fields, size, typ, count, n, n, data))


def pcd():
    pts = [(0.0, 0.0, 0.0), (1.0, 0.5, 0.25), (-1.0, 2.0, 0.5), (0.5, -0.5, 1.0), (2.0, 2.0, 2.0)]
    rgb = [0x00FF0000, 0x0000FF00, 0x000000FF, 0x00808080, 0x00FFFFFF]
    a = pcd_header("x y z rgb", "4 4 4 4", "F F F U", "1 1 1 1", len(pts), "ascii")
    for (x, y, z), c in zip(pts, rgb):
        a += "%g %g %g %d\n" % (x, y, z, c)
    put("pcd", "ascii_xyz_rgb.pcd", a)

    b = pcd_header("x y z intensity normal_x normal_y normal_z _ classification",
                   "4 4 4 4 4 4 4 1 1", "F F F F F F F U U", "1 1 1 1 1 1 1 4 1", len(pts),
                   "binary").encode()
    for i, (x, y, z) in enumerate(pts):
        b += struct.pack("<7f4BB", x, y, z, 0.1 * i, 0, 0, 1, 0, 0, 0, 0, i)
    put("pcd", "binary_intensity_normal_pad_class.pcd", b)

    # binary_compressed: each field's values for all points, one field after another.
    soa = b"".join(struct.pack("<f", p[k]) for k in range(3) for p in pts)
    soa += b"".join(struct.pack("<I", c) for c in rgb)
    z = lzf_compress(soa)
    c = pcd_header("x y z rgb", "4 4 4 4", "F F F U", "1 1 1 1", len(pts), "binary_compressed")
    put("pcd", "binary_compressed_xyz_rgb.pcd", c.encode() + struct.pack("<II", len(z), len(soa)) + z)

    many = pts * 4
    soa = b"".join(struct.pack("<d", p[k]) for k in range(3) for p in many)
    soa += bytes(i * 10 % 256 for i in range(len(many))) + bytes([20] * len(many))
    soa += bytes([30] * len(many))
    z = lzf_compress(soa)
    c = pcd_header("x y z red green blue", "8 8 8 1 1 1", "F F F U U U", "1 1 1 1 1 1",
                   len(pts) * 4, "binary_compressed")
    put("pcd", "binary_compressed_double_sep_rgb.pcd",
        c.encode() + struct.pack("<II", len(z), len(soa)) + z)

    put("pcd", "bad_points_over_file.pcd",
        pcd_header("x y z", "4 4 4", "F F F", "1 1 1", 1000000, "binary") + "abcd")
    put("pcd", "bad_compressed_size.pcd",
        pcd_header("x y z", "4 4 4", "F F F", "1 1 1", 2, "binary_compressed").encode()
        + struct.pack("<II", 4, 0x7FFFFFFF) + b"\x00abc")


# ---------------------------------------------------------------- LAS

def las_header(minor, fmt, rec_len, n, scale=0.01, offset=(100.0, 200.0, 0.0)):
    size = {2: 227, 3: 235, 4: 375}[minor]
    h = bytearray(size)
    h[0:4] = b"LASF"
    h[24], h[25] = 1, minor
    h[26:26 + 10] = b"make_corpu"
    struct.pack_into("<HHHIIBHI", h, 90, 1, 2024, size, size, 0, fmt, rec_len,
                     0 if minor == 4 else n)
    struct.pack_into("<3d3d", h, 131, scale, scale, scale, *offset)
    struct.pack_into("<6d", h, 179, 110, 100, 210, 200, 5, 0)
    if minor == 4:
        struct.pack_into("<Q", h, 247, n)
    return bytes(h)


def las():
    xyz = [(0, 0, 0), (1000, 0, 100), (0, 1000, 200), (1000, 1000, 500), (-5, 7, 9)]
    b = las_header(2, 3, 34, len(xyz))
    for i, (x, y, z) in enumerate(xyz):
        b += struct.pack("<3iHBBbBHd3H", x, y, z, 100 * i, 0x11, 2 + i, 0, 0, 1, 0.5 * i,
                         50 * i, 40, 200)
    put("las", "las12_format3_rgb.las", b)

    b = las_header(2, 1, 28 + 4, len(xyz))  # 4 extra bytes per record
    for i, (x, y, z) in enumerate(xyz):
        b += struct.pack("<3iHBBbBHd", x, y, z, 7 * i, 0x11, 6, 0, 0, 1, 0.0) + b"xtra"
    put("las", "las12_format1_extra_bytes.las", b)

    b = las_header(4, 7, 36, len(xyz), scale=0.001)
    for i, (x, y, z) in enumerate(xyz):
        b += struct.pack("<3iHBBBBhHd3H", x, y, z, 10 * i, 0x11, 0, 9 + i, 0, 0, 1, 1.0 * i,
                         1000 * i, 65535, 300)
    put("las", "las14_format7_rgb16.las", b)

    b = las_header(3, 0, 20, 2)
    for x, y, z in xyz[:2]:
        b += struct.pack("<3iHBBbBH", x, y, z, 1, 0x11, 2, 0, 0, 1)
    put("las", "las13_format0.las", b)

    # One point at -1.16e308: the bounding-box centre overflowed to -inf before the fix.
    b = las_header(2, 0, 20, 1, scale=1e303, offset=(0.0, 0.0, 0.0))
    b += struct.pack("<3iHBBbBH", -115790, 0, 0, 1, 0x11, 2, 0, 0, 1)
    put("las", "huge_coordinate_single_point.las", b)

    put("las", "bad_count_over_file.las", las_header(2, 0, 20, 1000) + bytes(40))
    put("las", "bad_laz.las", las_header(2, 0x83, 34, 1) + bytes(34))


# ---------------------------------------------------------------- XYZ

def xyz():
    put("xyz", "plain.xyz", "0 0 0\n1 0 0\n0 1 0\n0 0 1.5e-1\n")
    put("xyz", "rgb_commas_crlf.xyz", "# x,y,z,r,g,b\r\n1.5,2.5,3.5,255,0,0\r\n"
        "-1,-2,-3,0,255,0\r\n\r\n4;5;6;0;0;255\r\n")
    put("xyz", "pts_count_irgb.pts", "3\n0 0 0 -1200 10 20 30\n1 1 1 0 40 50 60\n"
        "2 2 2 1500 70 80 90\n")
    put("xyz", "float_colour_intensity.txt", "// comment\n0 0 0 0.5\t0.1 0.2 0.3\n"
        "1 2 3 0.25\t0.4 0.5 0.6\n")
    put("xyz", "two_blocks.pts", "2\n0 0 0 1\n1 1 1 2\n1\n5 5 5 3\n")
    put("xyz", "nan_row_no_newline.xyz", "0 0 0\nnan 1 1\n2 2 2")
    put("xyz", "bad_empty.xyz", b"")
    put("xyz", "bad_token.xyz", "0 0 0\n1 x 1\n")
    put("xyz", "bad_count_mismatch.pts", "5\n0 0 0\n1 1 1\n")


# ---------------------------------------------------------------- LZF, params

def lzf():
    def seed(name, raw):
        z = lzf_compress(raw)
        n = len(raw)
        put("lzf", name, bytes([n & 0xFF, (n >> 8) & 0xFF, (n >> 16) & 0x0F]) + z)

    seed("literals", bytes(range(100)))
    seed("run_dist1", b"a" * 300)
    seed("pattern_dist3", b"xyz" * 120 + b"end")
    seed("long_dist", bytes(range(256)) * 3 + bytes(40))
    seed("floats", b"".join(struct.pack("<f", i * 0.5) for i in range(200)))
    put("lzf", "empty", b"\x00\x00\x00")
    put("lzf", "bad_backref_before_start", b"\x10\x00\x00\x20\x05")
    put("lzf", "bad_literal_cut", b"\x05\x00\x00\x04ab")


def params():
    for i, kv in enumerate(["pipeline=points", "splat_scale=2.5", "lowpass=0", "point_size=3",
                            "point_budget=4000000000", "color=normal", "light=0.3,-0.4,1",
                            "background=0.1,0.2,0.3", "format=exr", "quality=100",
                            "subsampling=gray"]):
        put("params", "ok_%02d" % i, kv)
    for i, kv in enumerate(["nosuch=1", "quality=101", "light=1,2", "splat_scale=nan", "=1",
                            "pipeline", "point_budget=1.5",
                            # 9 after 130 zeros: was cut at 127 bytes and stored as 0
                            "background=0,0," + "0" * 130 + "9"]):
        put("params", "bad_%02d" % i, kv)


# ---------------------------------------------------------------- LAZ and COPC

DATA = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "data")


class ArithEncoder:
    """LASzip's arithmetic encoder, the exact inverse of laz_arith.h's decoder (a port of
    tests/tools/laz_tile.c's), for values coded with fresh models only: each model here codes
    one symbol, so no model is ever updated."""
    MIN = 0x01000000

    def __init__(self):
        self.base, self.length, self.out = 0, 0xFFFFFFFF, bytearray()

    def _carry(self):
        i = len(self.out)
        while i > 0 and self.out[i - 1] == 0xFF:
            i -= 1
            self.out[i] = 0
        if i > 0:
            self.out[i - 1] += 1

    def _renorm(self):
        while self.length < self.MIN:
            self.out.append(self.base >> 24)
            self.base = (self.base << 8) & 0xFFFFFFFF
            self.length = (self.length << 8) & 0xFFFFFFFF

    def _narrow(self, x, y):
        b = self.base
        self.base = (self.base + x) & 0xFFFFFFFF
        self.length = y - x
        if self.base < b:
            self._carry()
        self._renorm()

    def symbol(self, n, sym):
        """sym of a fresh model of n symbols: counts 1, distribution (2^31 / n) k >> 16."""
        dist = [(((0x80000000 // n) * k) & 0xFFFFFFFF) >> 16 for k in range(n + 1)]
        top, l = self.length, self.length >> 15
        self._narrow(dist[sym] * l, top if sym == n - 1 else dist[sym + 1] * l)

    def bit(self, b):
        """b of a fresh bit model (probability of 0: 2^12 of 2^13)."""
        x = (1 << 12) * (self.length >> 13)
        if b == 0:
            self.length = x
            self._renorm()
        else:
            self._narrow(x, self.length)

    def raw(self, v, bits):
        if bits > 19:
            self.raw(v & 0xFFFF, 16)
            v, bits = v >> 16, bits - 16
        l = self.length >> bits
        self._narrow(v * l, v * l + l)

    def integer(self, pred, real):
        """real against pred through a fresh 32-bit integer compressor (bits_high 8)."""
        corr = (real - pred) & 0xFFFFFFFF
        corr = corr - (1 << 32) if corr >= 1 << 31 else corr
        mag = corr - 1 if corr > 0 else -corr
        k = mag.bit_length()
        self.symbol(33, k)
        if k == 0:
            self.bit(corr)
        elif k < 32:
            c = (corr - 1 if corr > 0 else corr + (1 << k) - 1) & 0xFFFFFFFF
            if k <= 8:
                self.symbol(1 << k, c)
            else:
                self.symbol(256, c >> (k - 8))
                self.raw(c & ((1 << (k - 8)) - 1), k - 8)

    def done(self):
        b = self.base
        if self.length > 2 * self.MIN:
            self.base, self.length = (self.base + self.MIN) & 0xFFFFFFFF, self.MIN >> 1
        else:
            self.base, self.length = (self.base + (self.MIN >> 1)) & 0xFFFFFFFF, self.MIN >> 9
        if self.base < b:
            self._carry()
        self._renorm()
        return bytes(self.out) + bytes(4)


def laz_small(name, npts):
    """A one-chunk pointwise LAS 1.2 LAZ file of tests/data cut to its first npts points: the
    header's count, the chunk's first bytes (those points take fewer than three times their
    share of the chunk, plus slack) and a new chunk table (fixed chunk size: only the chunk's
    byte size is coded). A few hundred bytes of chunk instead of 10-30 KiB: the fuzzer
    decodes far fewer points per input and mutates bytes that are read."""
    with open(os.path.join(DATA, name), "rb") as f:
        b = bytearray(f.read())
    data_off = struct.unpack_from("<I", b, 96)[0]
    rec_len = struct.unpack_from("<H", b, 105)[0]
    count = struct.unpack_from("<I", b, 107)[0]
    table = struct.unpack_from("<Q", b, data_off)[0]
    chunk = b[data_off + 8:table]
    keep = min(len(chunk), rec_len + 3 * len(chunk) * npts // count + 64)
    e = ArithEncoder()
    e.integer(0, keep)
    out = b[:data_off] + struct.pack("<Q", data_off + 8 + keep) + chunk[:keep]
    out += struct.pack("<II", 0, 1) + e.done()
    struct.pack_into("<I", out, 107, npts)
    struct.pack_into("<5I", out, 111, npts, 0, 0, 0, 0)
    return bytes(out)


def laz():
    """LAZ files of tests/data cut to a few dozen points (laz_small), and broken ones."""
    for name, n in [("point10.las.laz", 40), ("point-time.las.laz", 30),
                    ("point-color.las.laz", 30), ("point-color-time.las.laz", 25),
                    ("extrabytes.laz", 20)]:
        put("laz", name, laz_small(name, n))
    b = bytearray(laz_small("point10.las.laz", 40))
    put("laz", "bad_cut_in_chunk.laz", bytes(b[:len(b) // 2]))
    w = bytearray(b)
    w[104] = 0x84  # waveform format 4
    w[105:107] = struct.pack("<H", 57)
    put("laz", "bad_waveform.laz", bytes(w))


def copc_info(root_off, root_size):
    # centre, half size, spacing, root page offset/size, gps min/max, 11 reserved
    return struct.pack("<5d2Q2d11Q", 0, 0, 0, 100, 1, root_off, root_size, 0, 1, *([0] * 11))


def copc_entry(level, x, y, z, off, size, count):
    return struct.pack("<4iQii", level, x, y, z, off, size, count)


def copc():
    """COPC hierarchies for the copc target: the info payload, then pages at offset 160."""
    # one page: the root with data (pointing at the info bytes), an empty child
    page = copc_entry(0, 0, 0, 0, 0, 64, 10) + copc_entry(1, 1, 0, 1, 0, 0, 0)
    put("copc", "one_page.bin", copc_info(160, len(page)) + page)
    # a root page linking to a child page
    child = copc_entry(2, 3, 1, 0, 8, 16, 5)
    root = copc_entry(0, 0, 0, 0, 0, 32, 7) + copc_entry(1, 1, 1, 1, 160 + 64, 32, -1)
    put("copc", "two_pages.bin", copc_info(160, len(root)) + root + child)
    # an empty root page
    put("copc", "empty_page.bin", copc_info(160, 0))
    # bad: a page that links to itself, a key outside its level, a page cut mid-entry
    loop = copc_entry(0, 0, 0, 0, 160, 32, -1)
    put("copc", "bad_self_link.bin", copc_info(160, 32) + loop)
    put("copc", "bad_key.bin", copc_info(160, 32) + copc_entry(1, 2, 0, 0, 0, 0, 0))
    put("copc", "bad_page_size.bin", copc_info(160, 40) + page)


def copc_from_laz(name, pages):
    """A small COPC file made from a LAZ file of tests/data cut to 40 points (laz_small): a
    "copc" info VLR (record 1) put before its VLRs and hierarchy pages appended at its end.
    The readers take a node's chunk from the hierarchy alone, so every node entry may point at
    the one chunk (a pointwise chunk decodes its first k points as a chunk of k). pages(off,
    size, count, root_off) gives the root page and the pages after it for that chunk (off,
    size bytes, count points) with the root page at root_off."""
    b = bytearray(laz_small(name, 40))
    hsize = struct.unpack_from("<H", b, 94)[0]
    data_off, nvlr = struct.unpack_from("<II", b, 96)
    count = struct.unpack_from("<I", b, 107)[0]
    table = struct.unpack_from("<Q", b, data_off)[0]
    shift = 54 + 160
    root_off = len(b) + shift
    root, rest = pages(data_off + 8 + shift, table - (data_off + 8), count, root_off)
    vlr = struct.pack("<H16sHH32s", 0, b"copc", 1, 160, b"copc info") + copc_info(root_off, len(root))
    out = b[:hsize] + vlr + b[hsize:]
    struct.pack_into("<II", out, 96, data_off + shift, nvlr + 1)
    struct.pack_into("<Q", out, data_off + shift, table + shift)
    return bytes(out + root + rest)


def copclevels():
    """Seeds of the copclevels target: byte 0 is the deepest level asked for (0-7), then a
    COPC file (copc_from_laz)."""
    def put_l(name, level, data):
        put("copclevels", name, bytes([level]) + data)

    def one(level, count_of):
        return lambda o, n, c, r: (copc_entry(level, 0, 0, 0, o, n, count_of(c)), b"")

    put_l("root_only_p10", 2, copc_from_laz("point10.las.laz", one(0, lambda c: c)))
    # levels 0, 1, 2 of 10, 25 and 40 points (of the one chunk)
    f = copc_from_laz("point10.las.laz", lambda o, n, c, r: (
        copc_entry(0, 0, 0, 0, o, n, 10) + copc_entry(1, 1, 0, 1, o, n, 25)
        + copc_entry(2, 3, 1, 2, o, n, c), b""))
    put_l("three_levels_p10", 1, f)
    put_l("three_levels_p10_all", 7, f)
    # the root page (3 entries) links to a child page holding a level-2 node; an empty node
    put_l("two_pages_rgb", 3, copc_from_laz("point-color.las.laz", lambda o, n, c, r: (
        copc_entry(0, 0, 0, 0, o, n, 15) + copc_entry(1, 0, 1, 0, 0, 0, 0)
        + copc_entry(1, 1, 1, 1, r + 96, 32, -1), copc_entry(2, 2, 3, 2, o, n, c))))
    # bad: no copc VLR; a node of more points than its chunk holds; no node at level 0
    put_l("bad_not_copc", 3, laz_small("point10.las.laz", 40))
    put_l("bad_count_over_chunk", 0, copc_from_laz("point10.las.laz", one(0, lambda c: 50 * c)))
    put_l("bad_nothing_at_level_0", 0, copc_from_laz("point10.las.laz", one(1, lambda c: c)))


LODSRC_EXT = {".ply": 0, ".las": 1, ".laz": 2, ".pcd": 3, ".xyz": 4, ".pts": 5, ".txt": 6,
              ".copc.laz": 7}


def lodsrc():
    """Seeds of the lodsrc target: byte 0 picks the extension (LODSRC_EXT) and, in its high 5
    bits, the piece size of the reads; then the file. Most are other targets' seeds (written
    before this runs)."""
    def put_s(name, ext, piece, data):
        put("lodsrc", name, bytes([LODSRC_EXT[ext] | piece << 3]) + data)

    def seed(target, name, ext, piece):
        with open(os.path.join(ROOT, target, name), "rb") as f:
            put_s(("bad_" if name.startswith("bad_") else "") + target + "_" +
                  name.replace("bad_", ""), ext, piece, f.read())

    seed("ply", "binary_le_rgba_quality.ply", ".ply", 0)   # streamed, floats and bytes
    seed("ply", "ascii_rgb_normal_faces.ply", ".ply", 3)   # read whole by pc_load
    seed("ply", "binary_be_face_first_intensity_radius.ply", ".ply", 1)
    seed("las", "las12_format3_rgb.las", ".las", 2)
    seed("las", "las14_format7_rgb16.las", ".las", 0)
    seed("laz", "point-color.las.laz", ".laz", 5)
    seed("pcd", "ascii_xyz_rgb.pcd", ".pcd", 0)
    seed("pcd", "binary_compressed_double_sep_rgb.pcd", ".pcd", 1)
    seed("xyz", "rgb_commas_crlf.xyz", ".xyz", 2)
    seed("xyz", "pts_count_irgb.pts", ".pts", 0)
    seed("xyz", "float_colour_intensity.txt", ".txt", 4)
    seed("xyz", "nan_row_no_newline.xyz", ".xyz", 1)
    seed("xyz", "bad_token.xyz", ".xyz", 0)
    seed("pcd", "bad_points_over_file.pcd", ".pcd", 0)
    # streamed PLY, per-field path: doubles, 16-bit colours, a NaN point (dropped), an extra
    # property; the vertex element first, a face element after it
    h = ("ply\nformat binary_little_endian 1.0\nelement vertex 5\nproperty double x\n"
         "property double y\nproperty double z\nproperty ushort red\nproperty ushort green\n"
         "property ushort blue\nproperty int id\nelement face 0\n"
         "property list uchar int vertex_indices\nend_header\n").encode()
    pts = [(0, 0, 0), (1.5, -2, 3), (float("nan"), 1, 1), (-4, 8, 0.25), (2, 2, 2)]
    for i, (x, y, z) in enumerate(pts):
        h += struct.pack("<3d3Hi", x, y, z, 1000 * i, 65535, 257 * i, i)
    put_s("ply_double_ushort_nan.ply", ".ply", 7, h)
    # streamed PLY as pc_read_ply reads it: version "1", float colours named diffuse_* (scaled
    # by 255), alpha; the stream's own header parser took neither name nor scale
    h = ("ply\nformat binary_little_endian 1\ncomment c\nelement vertex 3\nproperty float x\n"
         "property float y\nproperty float z\nproperty float diffuse_red\n"
         "property float diffuse_green\nproperty float diffuse_blue\nproperty uchar alpha\n"
         "end_header\n").encode()
    for i in range(3):
        h += struct.pack("<6fB", i, 2 * i, -i, 0.5, 0.25 * i, 1.0, 100 + i)
    put_s("ply_v1_float_diffuse_colours.ply", ".ply", 2, h)
    # refused by pc_read_ply, hence by the stream: a control byte in the header; a LAS file
    # named .xyz (pc_load reads by extension; the stream took it as LAS)
    put_s("bad_ply_control_byte.ply", ".ply", 0,
          b"ply\nformat binary_little_endian 1.0\nelement vertex 1\nproperty float x\x7f\n"
          b"property float y\nproperty float z\nend_header\n" + bytes(12))
    with open(os.path.join(ROOT, "las", "las12_format3_rgb.las"), "rb") as f:
        put_s("bad_las_named_xyz.xyz", ".xyz", 0, f.read())
    # the vertices whole, the faces after them cut short: pc_read_ply refuses the file
    h = (b"ply\nformat binary_little_endian 1.0\nelement vertex 3\nproperty float x\n"
         b"property float y\nproperty float z\nelement face 2\n"
         b"property list uchar int vertex_indices\nend_header\n")
    h += struct.pack("<9f", 0, 0, 0, 1, 0, 0, 0, 1, 0) + struct.pack("<B3i", 3, 0, 1, 2) + b"\x03"
    put_s("bad_ply_faces_cut.ply", ".ply", 0, h)
    put_s("bad_ply_count_over_file.ply", ".ply", 0,
          b"ply\nformat binary_little_endian 1.0\nelement vertex 9\nproperty float x\n"
          b"property float y\nproperty float z\nend_header\n" + bytes(12 * 3))


def campath():
    """Seeds of the campath target: an output pattern line, then a camera-path file. Valid
    seeds have a valid file (the pattern may be invalid: the target returns cp_load's code)."""
    cams = "0 0 5, 0 0 0, 0 1 0, 45\n1 0 5 0 0 0 0 1 0 50 # a comment\n\n# only a comment\n"
    put("campath", "zero_padded", "out/%05d.jpg\n" + cams)
    put("campath", "plain_tabs_crlf", "frames/f%d.png\n2\t0\t5\t0\t0\t0\t0\t1\t0\t30\r\n"
        "1e-3,2E2,-3.5,0,0,0,0,0,1,179.5\r\n")
    put("campath", "percent_space_pad", "%%lit_%3d.exr\n0 0 1 0 0 0 0 1 0 0.5")
    put("campath", "pattern_invalid_good_file", "out/%d_%d.raw\n" + cams)
    put("campath", "zero_flags", "a/b.c/%0007d\n" + cams)
    # the widths' limit exactly: 19 is a width, 20 is not (N < 20)
    put("campath", "width_19", "f%019d.png\n" + cams)
    put("campath", "width_20_refused", "f%20d.png\n" + cams)
    put("campath", "bad_nine_numbers", "x%d.jpg\n0 0 5 0 0 0 0 1 0\n")
    put("campath", "bad_fov_180", "x%d.jpg\n0 0 5 0 0 0 0 1 0 180\n")
    put("campath", "bad_no_cameras", "x%d.jpg\n# nothing\n\n")
    put("campath", "bad_nan_second_line", "x%d.jpg\n" + cams + "nan 0 5 0 0 0 0 1 0 45\n")


def shard():
    """Seeds of the shard target: byte 0 says which of --shard, --shards, JOB_COMPLETION_INDEX,
    SPLAT_SHARD_COUNT, SLURM_ARRAY_TASK_ID, SLURM_ARRAY_TASK_COUNT, SLURM_ARRAY_TASK_MIN are
    set (bit 0 to 6); then their values, one a line."""
    def put_s(name, mask, *fields):
        put("shard", name, bytes([mask]) + "\n".join(fields).encode())

    put_s("flag", 0x01, "3/8")
    put_s("flag_over_env", 0x15, "0/2", "", "1", "", "7")
    put_s("job_index_count", 0x0C, "", "", "5", "10")
    put_s("shards_job_index", 0x06, "", "4", "2")
    put_s("slurm_min", 0x70, "", "", "", "", "17", "4", "15")
    put_s("none", 0x00)
    put_s("bad_shards_alone", 0x02, "", "4")
    put_s("bad_index_at_count", 0x01, "8/8")
    put_s("bad_job_index_no_count", 0x04, "", "", "3")
    put_s("bad_plus_sign", 0x01, "+1/2")
    put_s("bad_tab_before_index", 0x0C, "", "", "\t5", "10")
    put_s("bad_slurm_min_over_id", 0x70, "", "", "", "", "3", "4", "5")


def token():
    """Seeds of the token target: byte 0 bits 0-1 the mode (0600 0400 0640 0604), bit 2 a
    symbolic link, bit 3 a directory, bit 4 a FIFO; then the file."""
    put("token", "line", b"\x00secret\n")
    put("token", "max_len", b"\x00" + b"t" * 4096)
    put("token", "max_len_crlf", b"\x00" + b"t" * 4096 + b"\r\n")
    put("token", "symlink_0400", b"\x05tok\r\n")
    put("token", "binary", b"\x00\x00\x01\xff\n\x00")
    put("token", "bad_group_readable", b"\x02secret")
    put("token", "bad_other_readable", b"\x03secret")
    put("token", "bad_only_newlines", b"\x00\n\r\n")
    put("token", "bad_over_max", b"\x00" + b"t" * 4097)
    put("token", "bad_directory", b"\x08x")
    put("token", "bad_fifo", b"\x10x")
    put("token", "bad_file_over_max_plus_2", b"\x00" + b"t" * 4096 + b"\n\n\n")


def mpimsg():
    """Seeds of the mpimsg target (server/mpi/mr_msg.h): byte 0 = 0, a command record (the
    target pads it with zeros to MR_CMD_BYTES); byte 0 = 1, a failure record."""
    def cmd(op, key, want_float=0, path=b"", cam=b"", par=b""):
        return (b"\x00" + struct.pack("<3I", op, key, want_float)
                + struct.pack("<H", len(path)) + path + struct.pack("<I", len(cam)) + cam
                + struct.pack("<I", len(par)) + par)
    put("mpimsg", "load", cmd(1, 1, path=b"/srv/clouds/bunny.ply"))
    put("mpimsg", "render", cmd(2, 3, 1, cam=camera(64, 48), par=params_payload()))
    put("mpimsg", "render_no_params", cmd(2, 3, 0, cam=camera(8, 8), par=struct.pack("<H", 0)))
    put("mpimsg", "quit", cmd(3, 0))
    put("mpimsg", "fail", b"\x01" + struct.pack("<i", -2) + b"rank 1 of 4: bad".ljust(512, b"\0"))
    put("mpimsg", "fail_unknown_code", b"\x01" + struct.pack("<i", 77) + b"x" * 512)
    put("mpimsg", "bad_unknown_op", cmd(7, 1))
    put("mpimsg", "bad_key_0", cmd(1, 0, path=b"a.ply"))
    put("mpimsg", "bad_nul_in_path", cmd(1, 1, path=b"a\0b.ply"))
    put("mpimsg", "bad_want_float_2", cmd(2, 3, 2, cam=camera(64, 48), par=params_payload()))
    put("mpimsg", "bad_camera_size", cmd(2, 3, 0, cam=camera(0, 48), par=params_payload()))
    put("mpimsg", "bad_padding", cmd(3, 0) + b"\x01")


def dispatch_seeds():
    """Seeds of the dispatch target (fuzz_one_dispatch): what one client sends to the daemon,
    whose data directory holds the 64-point cloud "sphere" and whose frames are at most
    128x128. Valid seeds get no ERROR; bad_* seeds each get one."""
    def session(*parts):
        seq = iter(range(1, 100))
        return b"".join(msg(t, p, next(seq)) for t, p in parts)
    put("dispatch", "hello_list_ping", session(("HELLO", hello()), ("LIST", b""),
                                               ("PING", struct.pack("<Q", 7)), ("BYE", b"")))
    put("dispatch", "open_render", session(
        ("HELLO", hello()), ("OPEN", s8("sphere")), ("CAMERA", camera(64, 48)),
        ("PARAMS", params_payload()), ("RENDER", b""), ("RENDER", b"")))
    put("dispatch", "stream", session(
        ("HELLO", hello()), ("OPEN", s8("sphere.xyz")), ("STREAM", struct.pack("<Bf", 1, 30.0)),
        ("CAMERA", camera(32, 32)), ("CAMERA", camera(48, 32)), ("PING", struct.pack("<Q", 1))))
    put("dispatch", "bad_not_found", session(("HELLO", hello()), ("OPEN", s8("nothing"))))
    put("dispatch", "bad_before_hello", msg("LIST"))
    put("dispatch", "bad_too_large", session(("HELLO", hello()), ("OPEN", s8("sphere")),
                                             ("CAMERA", camera(4096, 4096)), ("RENDER", b"")))
    put("dispatch", "bad_magic", b"GET / HTTP/1.1\r\n\r\n")


def lz4_literals(data):
    """One LZ4 block holding data as a single literal run (a valid block without matches)."""
    n = len(data)
    if n < 15:
        return bytes([n << 4]) + data
    ext, rest = b"", n - 15
    while rest >= 255:
        ext += b"\xff"
        rest -= 255
    return bytes([0xF0]) + ext + bytes([rest]) + data


def spl4(w, h, pixels):
    return b"SPL4" + struct.pack("<III", w, h, w * h * 4) + lz4_literals(pixels)


def frame_seeds():
    """Seeds of the client's frame decoder (fuzz_one_frame): byte 0 picks the format (0 JPEG,
    1 LZ4, 2 raw, 3 PNG; +4: the rest after bytes 1-2 is a whole FRAME payload), bytes 1-2 the
    announced width and height. The jpeg_* seeds are not written here: they are the 3 selector
    bytes followed by `splatd render tests/data/bun000.ply --pipeline points --size WxH -o
    x.jpg` (8x6 and 16x12), kept as they are."""
    px = bytes((i * 37) & 255 for i in range(4 * 4 * 3))
    put("frame", "raw_2x2", b"\x02\x02\x02" + bytes(range(16)))
    put("frame", "raw_4x3", b"\x02\x04\x03" + px)
    put("frame", "lz4_4x3", b"\x01\x04\x03" + spl4(4, 3, px))
    put("frame", "lz4_3x5_unannounced", b"\x01\x00\x00" + spl4(3, 5, bytes(60)))
    put("frame", "msg_raw_2x2", b"\x06\x00\x00" + frame(3, 2, 2, bytes(range(16))))
    put("frame", "msg_lz4_4x3", b"\x05\x00\x00" + frame(2, 4, 3, spl4(4, 3, px)))
    put("frame", "bad_raw_short", b"\x02\x02\x02" + bytes(15))
    put("frame", "bad_lz4_magic", b"\x01\x04\x03" + b"SPL5" + spl4(4, 3, px)[4:])
    put("frame", "bad_lz4_size", b"\x01\x04\x03" + spl4(4, 3, px)[:-1])
    put("frame", "bad_png", b"\x03\x00\x00\x89PNG\r\n\x1a\n")


def e57():
    """E57: small files of tests/data/e57 (other writers'), their XML sections, bit streams."""
    data = os.path.join(os.path.dirname(ROOT), "..", "data", "e57")
    for name in ("translationWithoutRotation.e57", "testWithNormals.e57",
                 "ColourRepresentation.e57"):
        with open(os.path.join(data, name), "rb") as f:
            raw = f.read()
        put("e57", name, raw)
        _, _, _, _, xo, xl, page = struct.unpack("<8sIIQQQQ", raw[:48])
        logical = b"".join(raw[p:p + page - 4] for p in range(0, len(raw), page))
        lo = xo // page * (page - 4) + xo % page
        put("e57xml", name.replace(".e57", ".xml"), bytes([17]) + logical[lo:lo + xl])
    with open(os.path.join(data, "empty.e57"), "rb") as f:
        put("e57", "bad_no_scans.e57", f.read())
    with open(os.path.join(data, "InvalidCVHeader.e57"), "rb") as f:
        put("e57", "bad_cv_header.e57", f.read())
    root = ('<e57Root type="Structure" xmlns="http://www.astm.org/COMMIT/E57/2010-e57-v1.0">'
            '<data3D type="Vector"><vectorChild type="Structure">%s<points type="CompressedVector"'
            ' fileOffset="48" recordCount="3"><prototype type="Structure">%s</prototype>'
            '<codecs type="Vector"/></points></vectorChild></data3D></e57Root>')
    sph = ('<sphericalRange type="ScaledInteger" minimum="0" maximum="1000" scale="0.01"/>'
           '<sphericalAzimuth type="Float" precision="single"/><sphericalElevation type="Float"/>'
           '<sphericalInvalidState type="Integer" minimum="0" maximum="2"/>')
    pose = ('<pose type="Structure"><rotation type="Structure"><w type="Float">0.5</w>'
            '<x type="Float">0.5</x><y type="Float">0.5</y><z type="Float">0.5</z></rotation>'
            '<translation type="Structure"><x type="Float">1e6</x></translation></pose>')
    put("e57xml", "spherical_pose.xml", bytes([3]) + (root % (pose, sph)).encode())
    put("e57xml", "bad_no_coordinates.xml", bytes([0]) + (root % ("", "<intensity type=\"Integer\"/>")).encode())
    put("e57xml", "bad_doctype.xml", b"\x05<!DOCTYPE e [<!ENTITY a 'b'>]><e57Root/>")
    # bit streams: width, kind, maximum below 2^width - 1, piece size, 0-bit count; bytes
    put("e57bits", "w13_int.bin", bytes([13, 0, 0, 3, 0]) + bytes(range(40)))
    put("e57bits", "w64_scaled.bin", bytes([64, 1, 0, 7, 0]) + bytes(range(255, 200, -1)))
    put("e57bits", "float.bin", bytes([0, 2, 0, 5, 0]) + struct.pack("<3f", 1.5, -2.0, 1e30))
    put("e57bits", "double.bin", bytes([0, 3, 0, 1, 0]) + struct.pack("<2d", 3.25, -1e300))
    put("e57bits", "zero_bits.bin", bytes([0, 0, 0, 1, 9]) + b"x")
    put("e57bits", "bad_over_max.bin", bytes([3, 0, 2, 2, 0]) + b"\xff\xff")


def main():
    proto()
    frame_seeds()
    dispatch_seeds()
    ply()
    pcd()
    las()
    xyz()
    lzf()
    params()
    laz()
    copc()
    e57()
    copclevels()
    lodsrc()
    campath()
    shard()
    token()
    mpimsg()
    total = sum(os.path.getsize(os.path.join(dp, f))
                for dp, _, fs in os.walk(ROOT) for f in fs)
    print("corpus: %d bytes under %s" % (total, ROOT))
    return 0


if __name__ == "__main__":
    sys.exit(main())
