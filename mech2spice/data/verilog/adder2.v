// 2-bit adder: the paper's example (10 NOR + 7 NOT = 17 gates).
module adder2(input [1:0] a, input [1:0] b, output [2:0] s);
  assign s = a + b;
endmodule
