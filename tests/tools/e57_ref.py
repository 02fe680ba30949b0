#!/usr/bin/env python3
"""e57_ref.py — a second E57 reader, written apart from server/io/e57_*.c, for the expected
values of tests/data/e57/SOURCES.md. It reads the whole file into memory, removes every page's
4 checksum bytes (checking each CRC-32C), parses the XML with xml.etree, joins each field's
buffers over all data packets into one byte string and unpacks it as one Python integer
(little-endian bit order). Poses are applied; points whose cartesianInvalidState or
sphericalInvalidState is not 0 are dropped.

    python3 tests/tools/e57_ref.py FILE.e57 ...

prints per file: valid points, bounds, and the sums of the raw colour channels and of the raw
intensities of the valid points (what the C tests compare against)."""
import math
import struct
import sys
import xml.etree.ElementTree as ET

NS = "{http://www.astm.org/COMMIT/E57/2010-e57-v1.0}"
NOR = "{http://www.libe57.org/E57_NOR_surface_normals.txt}"


def crc32c(data):
    crc = 0xFFFFFFFF
    for b in data:
        crc ^= b
        for _ in range(8):
            crc = (crc >> 1) ^ (0x82F63B78 if crc & 1 else 0)
    return crc ^ 0xFFFFFFFF


def logical(raw, page):
    out = bytearray()
    for p in range(0, len(raw), page):
        body, stored = raw[p:p + page - 4], raw[p + page - 4:p + page]
        if struct.pack(">I", crc32c(body)) != stored:
            raise ValueError("bad checksum in the page at %d" % p)
        out += body
    return bytes(out)


def fields_of(proto):
    """(name, kind, bits, min, scale, offset) per leaf, depth first."""
    out = []
    for el in proto:
        t = el.get("type")
        if t in ("Structure", "Vector"):
            out += [("", *f[1:]) for f in fields_of(el)]
        elif t in ("Integer", "ScaledInteger"):
            lo = int(el.get("minimum", -2**63))
            hi = int(el.get("maximum", 2**63 - 1))
            bits = (hi - lo).bit_length()
            out.append((el.tag, t, bits, lo, float(el.get("scale", 1)), float(el.get("offset", 0))))
        elif t == "Float":
            bits = 32 if el.get("precision") == "single" else 64
            out.append((el.tag, "Float", bits, 0, 1.0, 0.0))
        else:
            raise ValueError("field type " + t)
    return out


def values(stream, f, n):
    name, kind, bits, lo, scale, off = f
    v = int.from_bytes(stream, "little")
    out = []
    for i in range(n):
        raw = (v >> (i * bits)) & ((1 << bits) - 1) if bits else 0
        if kind == "Float":
            out.append(struct.unpack("<f" if bits == 32 else "<d",
                                     raw.to_bytes(bits // 8, "little"))[0])
        elif kind == "Integer":
            out.append(lo + raw)
        else:
            out.append((lo + raw) * scale + off)
    return out


def read(path):
    raw = open(path, "rb").read()
    _, _, _, _, xml_off, xml_len, page = struct.unpack("<8sIIQQQQ", raw[:48])
    lg = logical(raw, page)
    p2l = lambda off: off // page * (page - 4) + off % page
    root = ET.fromstring(lg[p2l(xml_off):p2l(xml_off) + xml_len])
    pts = []
    for scan in root.find(NS + "data3D"):
        cv = scan.find(NS + "points")
        n = int(cv.get("recordCount"))
        fl = fields_of(cv.find(NS + "prototype"))
        sec = p2l(int(cv.get("fileOffset")))
        slen, data = struct.unpack("<QQ", lg[sec + 8:sec + 24])
        streams = [b""] * len(fl)
        p = p2l(data)
        while p < sec + slen:
            kind, _, lm1 = struct.unpack("<BBH", lg[p:p + 4])
            if kind == 1:
                cnt, = struct.unpack("<H", lg[p + 4:p + 6])
                lens = struct.unpack("<%dH" % cnt, lg[p + 6:p + 6 + 2 * cnt])
                q = p + 6 + 2 * cnt
                for i, ln in enumerate(lens):
                    streams[i] += lg[q:q + ln]
                    q += ln
            p += lm1 + 1
        col = {}
        for f, s in zip(fl, streams):
            if f[0]:
                col[f[0].replace(NS, "").replace(NOR, "nor:")] = values(s, f, n)
        q = [1.0, 0.0, 0.0, 0.0]
        t = [0.0, 0.0, 0.0]
        pose = scan.find(NS + "pose")
        if pose is not None:
            r, tr = pose.find(NS + "rotation"), pose.find(NS + "translation")
            if r is not None:
                q = [float((r.find(NS + k).text or 0) if r.find(NS + k) is not None else d)
                     for k, d in zip("wxyz", (1, 0, 0, 0))]
            if tr is not None:
                t = [float(tr.find(NS + k).text or 0) for k in "xyz"]
        ln = math.sqrt(sum(c * c for c in q))
        w, x, y, z = (c / ln for c in q)
        R = [[1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
             [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
             [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)]]
        cmax = {f[0].replace(NS, ""): (f[3], f[3] + (1 << f[2]) - 1) for f in fl if f[1] == "Integer"}
        cart = "cartesianX" in col
        inv = col.get("cartesianInvalidState" if cart else "sphericalInvalidState", [0] * n)
        for i in range(n):
            if inv[i]:
                continue
            if cart:
                v = [col["cartesianX"][i], col["cartesianY"][i], col["cartesianZ"][i]]
            else:
                r_, az, el = (col["sphericalRange"][i], col["sphericalAzimuth"][i],
                              col["sphericalElevation"][i])
                v = [r_ * math.cos(el) * math.cos(az), r_ * math.cos(el) * math.sin(az),
                     r_ * math.sin(el)]
            wv = [sum(R[a][b] * v[b] for b in range(3)) + t[a] for a in range(3)]
            rgb = [col[c][i] for c in ("colorRed", "colorGreen", "colorBlue")] if "colorRed" in col else None
            nrm = None
            if "nor:normalX" in col:
                nv = [col["nor:normalX"][i], col["nor:normalY"][i], col["nor:normalZ"][i]]
                nrm = [sum(R[a][b] * nv[b] for b in range(3)) for a in range(3)]
            pts.append((wv, rgb, col["intensity"][i] if "intensity" in col else None, nrm,
                        cmax.get("colorRed")))
    return pts


for path in sys.argv[1:]:
    pts = read(path)
    print(path, len(pts), "points")
    if pts:
        for a in range(3):
            print("  %s [%r, %r]" % ("xyz"[a], min(p[0][a] for p in pts), max(p[0][a] for p in pts)))
        if pts[0][1] is not None:
            print("  colour sums", [sum(p[1][c] for p in pts) for c in range(3)])
            print("  first colours", [p[1] for p in pts[:3]])
            lo, hi = pts[0][4]
            to8 = lambda v: min(255, max(0, int((v - lo) * 255.0 / (hi - lo) + 0.5)))
            print("  8-bit colour sums (prototype range %d-%d)" % (lo, hi),
                  [sum(to8(p[1][c]) for p in pts) for c in range(3)])
        if pts[0][3] is not None:
            print("  normals", [p[3] for p in pts])
        if pts[0][2] is not None:
            print("  intensity sum", sum(p[2] for p in pts))
