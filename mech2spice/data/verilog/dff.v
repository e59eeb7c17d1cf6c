// One D flip-flop: the mechanical latch on its own.
module dff(input clk, input d, output reg q);
  always @(posedge clk) q <= d;
endmodule
