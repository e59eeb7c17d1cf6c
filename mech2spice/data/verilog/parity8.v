// Even parity of 8 bits: p = 1 when an odd number of bits of d are set.
module parity8(input [7:0] d, output p);
  assign p = ^d;
endmodule
