// The paper's 8-bit processor (Serra-Garcia 2019, Fig. 7), mapped by hand to 2-input NOR gates.
// Registers pc, A, B, C, D, overflow, and two phase bits; a datapath computes every candidate next
// value, a chain of 2:1 multiplexers per register picks one by the instruction in rdata[3:0].
// ISA, encoding and timing: mech2spice/cpu/isa.py, reports/cpu.md. LOAD_AB and LDNX_AB take two
// cycles (one memory read each): in the second, ld or nx is set and rdata is data, not an opcode.
// rst (synchronous: held for a clock edge) zeroes pc and the phase bits and suppresses writes;
// A, B, C, D and overflow are left as they are, so programs initialise the registers they read.
// The logic backend starts every flip-flop at 0 (pc = 0, fetch): the state after rst.
// (* keep *) holds this structure through Yosys/ABC, which maps the same logic ~10% larger.

// o = s ? y : x in 3 NOR gates per bit (ns = ~s is shared)
module mux8(input s, input ns, input [7:0] x, input [7:0] y, output [7:0] o);
  (* keep *) wire [7:0] t, u;
  genvar i;
  for (i = 0; i < 8; i = i + 1) begin : m
    nor (t[i], x[i], s); nor (u[i], y[i], ns); nor (o[i], t[i], u[i]);
  end
endmodule

module cpu(input clk, input rst, input [7:0] rdata, output [7:0] raddr, output [7:0] waddr,
           output [7:0] wdata, output we);
  reg [7:0] pc, a, b, c, d;
  reg ov, ld, nx;  // ld / nx: this cycle's rdata is LOAD_AB / LDNX_AB data
  genvar i;

  // ---- decoder: H[k] = fetch & rdata[3:2] == k, L[k] = rdata[1:0] == k (opcodes in isa.py)
  (* keep *) wire f0, nf0, f, nf, g0, g1, ng0, ng1;  // f = fetch: not a data cycle, not reset
  (* keep *) wire [3:0] no, H, nH, L, nL;
  for (i = 0; i < 4; i = i + 1) begin : inv
    not (no[i], rdata[i]);
  end
  nor (f0, ld, nx); not (nf0, f0); nor (f, nf0, rst); not (nf, f);
  nor (g0, nf, rdata[3]); nor (g1, nf, no[3]); not (ng0, g0); not (ng1, g1);
  nor (H[0], ng0, rdata[2]); nor (H[1], ng0, no[2]); nor (H[2], ng1, rdata[2]); nor (H[3], ng1, no[2]);
  nor (L[0], rdata[1], rdata[0]); nor (L[1], rdata[1], no[0]); nor (L[2], no[1], rdata[0]);
  nor (L[3], no[1], no[0]);
  for (i = 0; i < 4; i = i + 1) begin : inv2
    not (nH[i], H[i]); not (nL[i], L[i]);
  end
  // selects (s_*) and their complements (n_*) for the multiplexers
  (* keep *) wire s_ac, s_c, s_ab, s_bd, s_sh, s_add, s_nor, s_not, s_jmp, next_ld, next_nx;
  (* keep *) wire n_ac, n_c, n_ab, n_bd, n_sh, n_add, n_nor, n_not, n_jmp, n_ld, n_nx;
  nor (s_ac, nH[0], nL[0]);  nor (s_c, nH[0], rdata[1]);  // SWAP_AC; SWAP_AC or COPY_AC
  nor (s_ab, nH[0], nL[2]);  nor (s_bd, nH[0], nL[3]);    // SWAP_AB; SWAP_BD
  nor (s_sh, nH[1], rdata[1]);                            // RSL_D or RSA_D
  nor (s_add, nH[1], nL[2]); nor (s_nor, nH[1], nL[3]);   // APLUSB_TO_D; ANORB_TO_C
  nor (s_not, nH[2], nL[0]); nor (s_jmp, nH[2], nL[1]);   // NOT_C; JMP_C
  nor (we, nH[2], nL[2]);    nor (next_ld, nH[2], nL[3]);     // SAVE_AB; LOAD_AB
  nor (next_nx, nH[3], nL[3]);                                // LDNX_AB
  not (n_ac, s_ac); not (n_c, s_c); not (n_ab, s_ab); not (n_bd, s_bd); not (n_sh, s_sh);
  not (n_add, s_add); not (n_nor, s_nor); not (n_not, s_not); not (n_jmp, s_jmp);
  not (n_ld, ld); not (n_nx, nx);

  // ---- adder D = A + B (ripple carry, 9-NOR full adders); n, u, x, xo feed the comparators
  (* keep *) wire [7:0] n, t, u, x, xo, m, v, w, s;  // n = ~(a|b), u = a&~b, x = a xnor b
  (* keep *) wire [8:1] cy;
  for (i = 0; i < 8; i = i + 1) begin : add
    nor (n[i], a[i], b[i]); nor (t[i], a[i], n[i]); nor (u[i], b[i], n[i]); nor (x[i], t[i], u[i]);
    not (xo[i], x[i]);
    if (i == 0) begin : h
      assign s[0] = xo[0]; nor (cy[1], n[0], xo[0]);
    end else begin : f
      nor (m[i], x[i], cy[i]); nor (v[i], x[i], m[i]); nor (w[i], cy[i], m[i]);
      nor (s[i], v[i], w[i]); nor (cy[i+1], m[i], n[i]);
    end
  end
  // ngt = ~(A > B), rippled up from bit 0; eq = (A == B) as a tree over xo
  (* keep *) wire [7:0] ngt, gq;
  (* keep *) wire [3:0] p, np;
  (* keep *) wire [1:0] r, nr;
  (* keep *) wire eq;
  not (ngt[0], u[0]);
  for (i = 1; i < 8; i = i + 1) begin : cmp
    nor (gq[i], xo[i], ngt[i-1]); nor (ngt[i], u[i], gq[i]);
  end
  for (i = 0; i < 4; i = i + 1) begin : eqt
    nor (p[i], xo[2*i], xo[2*i+1]); not (np[i], p[i]);
  end
  nor (r[0], np[0], np[1]); nor (r[1], np[2], np[3]); not (nr[0], r[0]); not (nr[1], r[1]);
  nor (eq, nr[0], nr[1]);
  // skip = fetch & (GRT & A>B | DIF & A!=B | OVER & ov): the SKPNX opcodes share H[3]
  (* keep *) wire nov, t_gt, t_ne, t_ov, k1, k2, nin, skip;
  not (nov, ov);
  nor (t_gt, nL[0], ngt[7]); nor (t_ne, nL[1], eq); nor (t_ov, nL[2], nov);
  nor (k1, t_gt, t_ne); not (k2, k1); nor (nin, k2, t_ov); nor (skip, nH[3], nin);

  // ---- next pc before JMP_C: pc + 1 + skip, but pc + 0 in a LOAD_AB data cycle
  (* keep *) wire [7:0] np_, pn, pk, ps, ki, nki;  // ki: what bit i adds; pk: its carry out
  (* keep *) wire [6:1] nk;
  nor (ki[0], skip, ld); not (nki[0], ki[0]);
  nor (nki[1], skip, pk[0]); not (ki[1], nki[1]);  // bit 1 adds skip (never together with a carry)
  assign ki[7:2] = pk[6:1];
  assign nki[7:2] = nk[6:1];
  for (i = 0; i < 8; i = i + 1) begin : inc
    not (np_[i], pc[i]); nor (pn[i], pc[i], ki[i]); nor (pk[i], np_[i], nki[i]); nor (ps[i], pn[i], pk[i]);
  end
  for (i = 1; i < 7; i = i + 1) begin : ninc
    not (nk[i], pk[i]);
  end

  // ---- register multiplexers: hold, then each source in turn
  (* keep *) wire [7:0] nc;
  (* keep *) wire nd7, sh7;
  for (i = 0; i < 8; i = i + 1) begin : cn
    not (nc[i], c[i]);
  end
  not (nd7, d[7]); nor (sh7, no[0], nd7);  // RSA_D keeps bit 7, RSL_D clears it
  (* keep *) wire [7:0] a1, a2, next_a, b1, b2, next_b, c1, c2, next_c, d1, d2, next_d, p1, next_pc;
  mux8 ma1(s_ac, n_ac, a, c, a1);       mux8 ma2(s_ab, n_ab, a1, b, a2);    mux8 ma3(nx, n_nx, a2, rdata, next_a);
  mux8 mb1(s_bd, n_bd, b, d, b1);       mux8 mb2(s_ab, n_ab, b1, a, b2);    mux8 mb3(ld, n_ld, b2, rdata, next_b);
  mux8 mc1(s_c, n_c, c, a, c1);         mux8 mc2(s_not, n_not, c1, nc, c2); mux8 mc3(s_nor, n_nor, c2, n, next_c);
  mux8 md1(s_bd, n_bd, d, b, d1);       mux8 md2(s_add, n_add, d1, s, d2);
  mux8 md3(s_sh, n_sh, d2, {sh7, d[7:1]}, next_d);
  mux8 mp(s_jmp, n_jmp, ps, c, p1);    mux8 mr(ld, n_ld, pc, a, raddr);
  (* keep *) wire [7:0] np1;
  for (i = 0; i < 8; i = i + 1) begin : rs
    not (np1[i], p1[i]); nor (next_pc[i], np1[i], rst);
  end
  (* keep *) wire ot, ou, next_ov;
  nor (ot, ov, s_add); nor (ou, cy[8], n_add); nor (next_ov, ot, ou);
  assign waddr = b;
  assign wdata = a;
  always @(posedge clk) begin
    a <= next_a; b <= next_b; c <= next_c; d <= next_d; pc <= next_pc; ov <= next_ov; ld <= next_ld; nx <= next_nx;
  end
endmodule
