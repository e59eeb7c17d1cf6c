// ISCAS-89 s27, public benchmark netlist. Source: github.com/j0rban/Seq2Comb, path s27.bench,
// commit 71c9cd3e769dfda47aa66cc40295092d4c9e5801 (text below unchanged apart from this comment).
// 4 inputs
// 1 outputs
// 3 D-type flipflops
// 2 inverters
// 8 gates (1 ANDs + 1 NANDs + 2 ORs + 4 NORs)
// Transformed by scripts/iscas89_reset.py (do not edit): every flip-flop is a posedge flip-flop with a
// synchronous reset RST (to 0), and the flip-flops are exposed as the output port STATE
// (STATE[i] = the i-th flip-flop of the netlist, in file order).

module s27(RST,STATE,CK,G0,G1,G2,G3,G17);
input RST,CK;
output [2:0] STATE;
assign STATE = {G7,G6,G5};
input G0,G1,G2,G3;
output G17;
  wire G10,G11,G12,G13,G14,G15,G16,G5,G6,G7,G8,G9;

  dff_rst DFF_0(CK,G5,G10,RST);
  dff_rst DFF_1(CK,G6,G11,RST);
  dff_rst DFF_2(CK,G7,G13,RST);
  not G_3(G14,G0);
  not G_4(G17,G11);
  and G_5(G8,G14,G6);
  or G_6(G15,G12,G8);
  or G_7(G16,G3,G8);
  nand G_8(G9,G16,G15);
  nor G_9(G10,G14,G11);
  nor G_10(G11,G5,G9);
  nor G_11(G12,G1,G7);
  nor G_12(G13,G2,G12);

endmodule

module dff_rst (CK,Q,D,R);
input CK,D,R;
output Q;
reg Q;
always @(posedge CK) Q <= R ? 1'b0 : D;
endmodule
