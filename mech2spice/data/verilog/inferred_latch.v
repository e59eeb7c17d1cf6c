// A level-sensitive latch inferred from an incomplete combinational block (synth must refuse).
module inferred_latch(input en, input d, output reg q);
  always @* if (en) q = d;
endmodule
