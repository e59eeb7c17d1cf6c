// An asynchronous reset: the mechanical latch cannot honour it (synth must refuse).
module async_reset(input clk, input rst, input d, output reg q);
  always @(posedge clk or posedge rst)
    if (rst) q <= 1'b0;
    else q <= d;
endmodule
