// A combinational loop (a NAND feeding itself): synth must refuse it.
module loop(input a, output y);
  assign y = ~(y & a);
endmodule
