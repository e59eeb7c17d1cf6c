// Finite-state machine (paper Fig. 5c): a state register of 4 latches, one-hot, and a combinational
// transition function. It detects the input sequence 1,1,0,1 (overlapping); `found` is registered.
module fsm(input clk, input rst, input x, output reg [3:0] state, output reg found);
  // state[0]: nothing seen, state[1]: "1", state[2]: "11", state[3]: "110"
  always @(posedge clk)
    if (rst) begin
      state <= 4'b0001;
      found <= 1'b0;
    end else begin
      state[0] <= ~x & (state[0] | state[1] | state[3]);
      state[1] <= x & (state[0] | state[3]);
      state[2] <= x & (state[1] | state[2]);
      state[3] <= ~x & state[2];
      found <= x & state[3];
    end
endmodule
