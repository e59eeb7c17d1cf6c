"""How Icarus runs an always block that reads a signal its sensitivity list leaves out (docs/rtl.md, "Another
name of a listed signal"): the block `always @(a or b)`, declared before the assign it reads, against the same
block written `@*`, for three kinds of left-out signal.  Prints the reads that differ of 1000 (500 after both
inputs change at once, 500 after each input changes alone).

    python scripts/sensitivity_alias_icarus.py
"""
from __future__ import annotations

import subprocess
import tempfile
from pathlib import Path

KINDS = {"another name (assign bs = b)": "b",
         "logic (assign bs = ~b & a)": "~b & a",
         "a concatenation of slices": "{b[1:0], b[3:2]}"}

TEXT = """module listed(input [3:0] a, input [3:0] b, output reg [4:0] r, output reg [4:0] s);
  always @(a or b) r <= as + bs;
  always @(a or b) s = as ^ {{bs, 1'b0}};
  wire signed [3:0] as;
  wire signed [3:0] bs;
  assign as = a;
  assign bs = {rhs};
endmodule
module star(input [3:0] a, input [3:0] b, output reg [4:0] r, output reg [4:0] s);
  wire signed [3:0] as = a;
  wire signed [3:0] bs = {rhs};
  always @* r <= as + bs;
  always @* s = as ^ {{bs, 1'b0}};
endmodule
module tb;
  reg [3:0] a, b; wire [4:0] r, r2, s, s2; integer i, bad;
  listed u(a, b, r, s); star v(a, b, r2, s2);
  initial begin bad = 0;
    for (i = 0; i < 500; i = i + 1) begin a = $random; b = $random; #10; if (r !== r2 || s !== s2) bad = bad + 1; end
    for (i = 0; i < 500; i = i + 1) begin a = $random; #10; b = $random; #10;
      if (r !== r2 || s !== s2) bad = bad + 1; end
    $display("%0d", bad);
  end
endmodule
"""


def differences(rhs: str, generation: str) -> int:
    with tempfile.TemporaryDirectory() as tmp:
        src = Path(tmp, "t.v")
        src.write_text(TEXT.format(rhs=rhs))
        subprocess.run(["iverilog", generation, "-o", "t.vvp", str(src)], cwd=tmp, check=True)
        return int(subprocess.run(["vvp", "-n", "t.vvp"], cwd=tmp, check=True, capture_output=True,
                                  text=True).stdout.split()[0])


def main() -> None:
    version = subprocess.run(["iverilog", "-V"], capture_output=True, text=True).stdout.splitlines()[0]
    print(version)
    for kind, rhs in KINDS.items():
        print(f"{kind}: " + ", ".join(f"{g} {differences(rhs, g)} of 1000 reads differ" for g in ("-g2005", "-g2012")))


if __name__ == "__main__":
    main()
