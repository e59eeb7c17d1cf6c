// Syntax error on line 5 (dangling operator): synth must report that line.
module bad_syntax(input a, input b, output y);
  wire w;
  assign w = a & b;
  assign y = w | ;
endmodule
