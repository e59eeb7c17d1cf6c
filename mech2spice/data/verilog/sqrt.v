// Integer square root by binary search (paper Fig. 6): one result bit per clock cycle.
// The all-zero state is the start state (step 0 tries bit 5), so from power-up or after rst,
// six cycles later root = floor(sqrt(n)) and it then holds.
module sqrt(input clk, input rst, input [11:0] n, output reg [5:0] root);
  reg [2:0] step;                          // the result bit being decided is bit 5 - step
  wire [5:0] trial = root | (6'b100000 >> step);
  wire [11:0] square = trial * trial;
  always @(posedge clk)
    if (rst) begin
      root <= 6'd0;
      step <= 3'd0;
    end else if (step != 3'd6) begin
      if (square <= n) root <= trial;
      step <= step + 3'd1;
    end
endmodule
