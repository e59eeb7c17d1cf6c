// Integer square root by binary search (paper Fig. 6): one result bit per clock cycle.
// Cycle 0 with rst=1 loads root=0 and the trial bit 32; six cycles later root = floor(sqrt(n)).
module sqrt(input clk, input rst, input [11:0] n, output reg [5:0] root);
  reg [5:0] trial_bit;
  wire [5:0] trial = root | trial_bit;
  wire [11:0] square = trial * trial;
  always @(posedge clk)
    if (rst) begin
      root <= 6'd0;
      trial_bit <= 6'b100000;
    end else begin
      if (square <= n) root <= trial;
      trial_bit <= trial_bit >> 1;
    end
endmodule
