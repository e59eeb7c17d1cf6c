// An asynchronous reset: the latch's forcing input holds it at 0 while rst is high, without the clock
// (docs/rtl.md).
module async_reset(input clk, input rst, input d, output reg q);
  always @(posedge clk or posedge rst)
    if (rst) q <= 1'b0;
    else q <= d;
endmodule
