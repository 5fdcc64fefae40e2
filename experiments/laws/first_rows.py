"""The first ROWS rows of a C-order float64 .npy matrix, without NumPy:
python3 first_rows.py IN.npy ROWS OUT.npy"""
import ast
import sys

source, rows, target = sys.argv[1], int(sys.argv[2]), sys.argv[3]
data = open(source, "rb").read()
header_len = int.from_bytes(data[8:10], "little")
header = ast.literal_eval(data[10 : 10 + header_len].decode("latin1"))
assert header["descr"] == "<f8" and not header["fortran_order"], header
total, cols = header["shape"]
rows = min(rows, total)
body = data[10 + header_len : 10 + header_len + rows * cols * 8]
text = str({"descr": "<f8", "fortran_order": False, "shape": (rows, cols)}).encode("latin1")
pad = 64 - (10 + len(text) + 1) % 64
text += b" " * pad + b"\n"
open(target, "wb").write(b"\x93NUMPY\x01\x00" + len(text).to_bytes(2, "little") + text + body)
