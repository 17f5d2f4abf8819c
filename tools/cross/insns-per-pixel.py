#!/usr/bin/env python3
"""Instructions per output pixel of the warp's RGB block loop (4 pixels per iteration), counted in
the disassembly of src/warp/sample.o: the loop runs from the branch target of the 'any pixel
outside?' test (pmovmskb on SSE2, umaxv on NEON) through that test's branch, header included.
    tools/cross/insns-per-pixel.py OBJDUMP OBJECT      e.g. aarch64-linux-gnu-objdump build-arm64/src/warp/sample.o
"""
import re, subprocess, sys

objdump, obj = sys.argv[1], sys.argv[2]
text = subprocess.run([objdump, "-d", "--no-show-raw-insn", obj], check=True, capture_output=True, text=True).stdout
fn = re.search(r"<warp_sample_row>:\n(.*?)(?:\n\n|\Z)", text, re.S).group(1)
insns = []
for line in fn.splitlines():
    m = re.match(r"\s*([0-9a-f]+):\s+(\S+)\s*(.*)", line)
    if m:
        insns.append((int(m.group(1), 16), m.group(2), m.group(3)))
check = next(i for i, (_, op, _a) in enumerate(insns) if op in ("pmovmskb", "umaxv"))
branch = next(i for i in range(check, len(insns))
              if re.match(r"(j[a-z]+|b\.[a-z]+|cbn?z|tbn?z)$", insns[i][1]))
target = int(re.search(r"\b([0-9a-f]+) <", insns[branch][2]).group(1), 16)
loop = [x for x in insns if target <= x[0] <= insns[branch][0]]
ops = {}
for _, op, _a in loop:
    ops[op] = ops.get(op, 0) + 1
print(f"{obj}: {len(loop)} instructions per 4 pixels = {len(loop) / 4:.2f} per pixel")
print("  " + ", ".join(f"{op} {n}" for op, n in sorted(ops.items(), key=lambda t: -t[1])))
