"""Stage the public RTL suite (issue 34) from fetched mirrors of its source repositories: one folder per
design under $MECH2SPICE_BENCHMARKS/rtl with the design as one file, and manifest.json naming each one's
repository, paths, commit, sha256 and licence as stated (scripts/rtl_suite.py reads it).

    # first bring each repository named below as a bare mirror (the search tool's `fetch`, or git clone
    # --mirror into $MECH2SPICE_MIRRORS/OWNER+NAME/repo)
    MECH2SPICE_BENCHMARKS=DIR python scripts/rtl_suite_stage.py

The design files stay out of git (their licences vary or are not stated); this script and the manifest's
provenance are what make the suite reproducible.  Multi-file designs are joined in the order listed, their
`include lines of bundled files removed.
"""
import json, os, re, subprocess, hashlib
from pathlib import Path
M = Path(os.environ.get("MECH2SPICE_MIRRORS", "/work/.mirror"))
OUT = Path(os.environ.get("MECH2SPICE_BENCHMARKS", "benchmarks")) / "rtl"
def show(repo, path, rev="HEAD"):
    return subprocess.run(["git", "-C", str(M / repo.replace("/", "+") / "repo"), "show", f"{rev}:{path}"],
                          capture_output=True, check=True).stdout.decode("utf-8", "replace")
def commit(repo, rev="HEAD"):
    return subprocess.run(["git", "-C", str(M / repo.replace("/", "+") / "repo"), "rev-parse", f"{rev}^{{commit}}"],
                          capture_output=True, text=True, check=True).stdout.strip()
D = []
def add(name, repo, paths, top, clock=None, reset=None, level=None, licence="not stated", kind="", ext=".v", note="",
        rev="HEAD", harness="", convert=None, join="blank"):
    """rev: the commit the design was taken at (the mirror's HEAD when not named); harness: Verilog appended after
    the files (a small wrapper around public modules); convert: "iscas89_reset" for an ISCAS-89 .bench netlist;
    join: how several files are joined: "blank" (a blank line between them), "lines" (each file's lines, no blank
    line between) or "cat" (the bytes as they are, as `cat` joins them: a file without a final newline runs into
    the next)."""
    D.append(dict(name=name, repo=repo, paths=paths if isinstance(paths, list) else [paths], top=top, clock=clock,
                  reset=reset, reset_level=level, licence=licence, kind=kind, ext=ext, note=note, rev=rev,
                  harness=harness, convert=convert, join=join))
C = "alifahmed/conquest"
for b, top in [("b01", "b01"), ("b06", "b06"), ("b10", "b10"), ("b11", "b11"), ("b14", "b14")]:
    add(f"itc99_{b}", C, f"test/{b}/src/{b}.v", top, "clock", "reset", "high-sync", kind="ITC'99 RTL (Verilog port)")
V = "chenty2002/ChiselProjects"
for b in ["b02", "b03", "b04", "b05", "b07", "b08", "b09", "b12", "b13"]:
    add(f"itc99_{b}_vis", V, f"vis-verilog-models-1.3/ITC99/{b}/{b}.v", b, "clock", kind="ITC'99 RTL (VIS translation, F. Somenzi)", ext=".sv")
L = "lsils/benchmarks"
for f in ["random_control/ctrl", "random_control/router", "random_control/int2float", "random_control/cavlc",
          "random_control/dec", "random_control/priority", "random_control/i2c", "arithmetic/adder",
          "arithmetic/bar", "arithmetic/max"]:
    n = f.split("/")[1]
    add(f"epfl_{n}", L, f + ".v", None, licence="MIT", kind="EPFL combinational")
I = "ispras/hdl-benchmarks"
add("oc_i2c_master", I, ["iwls05/opencores/rtl/i2c/i2c_master_defines.v", "iwls05/opencores/rtl/i2c/i2c_master_bit_ctrl.v",
    "iwls05/opencores/rtl/i2c/i2c_master_byte_ctrl.v", "iwls05/opencores/rtl/i2c/i2c_master_top.v"],
    "i2c_master_top", "wb_clk_i", "wb_rst_i", "high-sync (+ arst_i async)", kind="OpenCores I2C master (IWLS'05)")
add("oc_eth_crc", I, "iwls05/opencores/rtl/ethernet/eth_crc.v", "eth_crc", "Clk", "Reset", "high-async", kind="OpenCores Ethernet CRC (IWLS'05)")
add("oc_minirisc_alu", I, ["quip/oc_minirisc/primitives.v", "quip/oc_minirisc/alu.v"], "alu", kind="OpenCores mini-RISC ALU (QUIP)")

add("sync_fifo", "mohamedsharith/verilog", "SEQUENTIAL/FIFO_SYNCH/synch_fifo.v", "syn_fifo", "clk", "reset", "low-sync", kind="sync FIFO with a memory")
add("gcd_rst_n", "lawrence910426/LogicDesign", "Lab4-5-Redemption/Lab5_Team3_Greatest_Common_Divisor.v", "Greatest_Common_Divisor", "clk", "rst_n", "high-sync (named rst_n)", kind="GCD FSM")
add("uart_tx_rv32s", "RISC-KC/basic_rv32s", "guidelines/clean_rtl/46F5SP_SoC/UART_TX.v", "UARTTX", "clk", "reset", "high-async", licence="see repository LICENSE", kind="UART transmitter")
add("uart_tx_pdp8", "penguin359/pdp8", "uarttx.v", "uarttx", "clk", "rst", "high-async", kind="UART transmitter with `reg x = 0` initialiser")
add("spi_master", "PratikBKadam/spi-master-slave-RTL", "spi_master/spi_master.v", "spi_master", "clk", "rst", "mixed async", kind="SPI master (both clock edges)")
add("rom_dds", "joyobama/FPGA_DDS", "tb/ROM_behavior.v", "ROM_behavior", "clk", kind="`initial` ROM, registered read")
add("regfile_tristate", "pedromello18/ECE350FinalProject", ["cp2-regfile/dffe_ref.v", "cp2-regfile/my_tri.v", "cp2-regfile/decoder32.v",
    "cp2-regfile/single_reg.v", "cp2-regfile/regfile.v"], "regfile", "clock", "ctrl_reset", "high-async", kind="register file with internal tri-state read buses")
R = "Sid-Rau/RTLLM"; B = "benchmark/"
for n, p, top, clk, rst, lvl, kind in [
    ("rtllm_asyn_fifo", "Memory/FIFO/asyn_fifo/verified_asyn_fifo.v", "verified_asyn_fifo", "wclk,rclk", "wrstn,rrstn", "low-async", "async FIFO, two clocks, dual-port RAM"),
    ("rtllm_ram", "Miscellaneous/RISC-V/RAM/verified_RAM.v", "verified_RAM", "clk", "rst_n", "low-async", "RAM (memory)"),
    ("rtllm_rom", "Miscellaneous/RISC-V/ROM/verified_ROM.v", "ROM", None, None, None, "`initial` ROM, combinational read"),
    ("rtllm_lfsr", "Memory/Shifter/LFSR/verified_LFSR.v", "LFSR", "clk", "rst", "high-async", "LFSR"),
    ("rtllm_lifo", "Memory/LIFO/LIFObuffer/verified_LIFObuffer.v", None, "Clk", "Rst", "", "LIFO with a memory"),
    ("rtllm_alu", "Miscellaneous/RISC-V/alu/verified_alu.v", None, None, None, None, "RISC-V ALU"),
    ("rtllm_traffic_light", "Miscellaneous/Others/traffic_light/verified_traffic_light.v", None, "clk", "rst_n", "low-async", "traffic light FSM"),
    ("rtllm_calendar", "Miscellaneous/Others/calendar/verified_calendar.v", None, "CLK", "RST", "high-async", "calendar counter"),
    ("rtllm_counter_12", "Control/Counter/counter_12/verified_counter_12.v", None, "clk", "rst_n", "low-async", "counter"),
    ("rtllm_seq_detector", "Control/Finite State Machine/sequence_detector/verified_sequence_detector.v", None, "clk", "rst_n", "low-async", "sequence detector FSM"),
    ("rtllm_accu", "Arithmetic/Accumulator/accu/verified_accu.v", None, "clk", "rst_n", "low-async", "accumulator"),
    ("rtllm_multi_pipe_4bit", "Arithmetic/Multiplier/multi_pipe_4bit/verified_multi_pipe_4bit.v", None, "clk", "rst_n", "low-async", "pipelined multiplier"),
    ("rtllm_radix2_div", "Arithmetic/Divider/radix2_div/verified_radix2_div.v", None, "clk", "rst", "", "radix-2 divider"),
    ("rtllm_width_8to16", "Miscellaneous/Others/width_8to16/verified_width_8to16.v", None, "clk", "rst_n", "low-async", "width converter"),
    ("rtllm_barrel_shifter", "Memory/Shifter/barrel_shifter/verified_barrel_shifter.v", "barrel_shifter", None, None, None, "barrel shifter"),
    ("rtllm_adder_bcd", "Arithmetic/Adder/adder_bcd/verified_adder_bcd.v", None, None, None, None, "BCD adder"),
    ("rtllm_edge_detect", "Miscellaneous/Others/edge_detect/verified_edge_detect.v", None, "clk", "rst_n", "low-async", "edge detector"),
    ("rtllm_freq_divbyodd", "Miscellaneous/Frequency divider/freq_divbyodd/verified_freq_divbyodd.v", None, "clk", "rst_n", "low-async", "odd divider (both edges)"),
]:
    add(n, R, B + p, top, clk, rst, lvl, licence="MIT (RTLLM)", kind=kind)


# Designs added to the suite by hand after this script was written (sessions 24-28, 101 rows): each as its row in
# docs/rtl_suite.json names it (repository, commit, paths, clock, licence, kind).  The rows do not record top, reset or
# the four harnesses: top is the files' one root module (ROM_sinus for sim_rom.v, which has six; the harness's own
# module for the four harness rows), reset and its level are the ones verify chose (rtl_suite.py passes no reset),
# and the harnesses are rewritten from the rows' one-line descriptions, not the text measured before (bsc_counter8's
# init 8'h55 chosen because it gives the row's 281 gates; mcj_hamming gives 727 gates for 724, cal_bus 419 for 403).  Several files
# are joined without a blank line (join="lines"): q_oc_gpio's and q_oc_rtc's refusals name lines 500 and 549 so;
# nl_smgame byte for byte (join="cat"): Icarus's syntax error at line 435 is there only so.
H = {}
H['bsc_counter8'] = """\
module counter8(input CLK, input RST, output [7:0] Q_OUT, input [7:0] DATA_A, input ADDA, input [7:0] DATA_B,
                input ADDB, input [7:0] DATA_C, input SETC, input [7:0] DATA_F, input SETF);
  Counter #(.width(8), .init(8'h55)) counter(.CLK(CLK), .RST(RST), .Q_OUT(Q_OUT), .DATA_A(DATA_A), .ADDA(ADDA),
    .DATA_B(DATA_B), .ADDB(ADDB), .DATA_C(DATA_C), .SETC(SETC), .DATA_F(DATA_F), .SETF(SETF));
endmodule
"""
H['nl_fifo16'] = """\
module fifo16(input i_Rst_L, input i_Clk, input i_Wr_DV, input [3:0] i_Wr_Data, input [3:0] i_AF_Level,
              output o_AF_Flag, output o_Full, input i_Rd_En, output o_Rd_DV, output [3:0] o_Rd_Data,
              input [3:0] i_AE_Level, output o_AE_Flag, output o_Empty);
  FIFO #(.WIDTH(4), .DEPTH(16)) fifo
    (.i_Rst_L(i_Rst_L), .i_Clk(i_Clk),
     .i_Wr_DV(i_Wr_DV), .i_Wr_Data(i_Wr_Data), .i_AF_Level(i_AF_Level), .o_AF_Flag(o_AF_Flag), .o_Full(o_Full),
     .i_Rd_En(i_Rd_En), .o_Rd_DV(o_Rd_DV), .o_Rd_Data(o_Rd_Data), .i_AE_Level(i_AE_Level), .o_AE_Flag(o_AE_Flag),
     .o_Empty(o_Empty));
endmodule
"""
H['mcj_hamming'] = """\
module mcj_hamming(
  input wire [10:0] mdata,                 // message
  input wire [3:0] pos1, input wire flip1, // up to two bits of the SECDED block flipped on the way
  input wire [3:0] pos2, input wire flip2,
  output wire [10:0] decoded, output wire d_err
);
  wire [15:0] block;
  hamming_encoder_ext #(.R_VALUE(4)) enc(.mdata(mdata), .bdata(block));
  hamming_decoder_ext #(.R_VALUE(4)) dec(.bdata(block ^ (flip1 ? 16'd1 << pos1 : 16'd0) ^ (flip2 ? 16'd1 << pos2 : 16'd0)), .mdata(decoded), .d_err(d_err));
endmodule
"""
H['cal_bus'] = """\
module cal_bus(input clock, input reset, input [7:0] data, input drive,
               input ir_read, input ir_write, input a_in, input a_out, input b_in, input b_out,
               input alu_out, input subtract, output [7:0] instruction, output [7:0] bus_value);
  wire [7:0] bus;
  // one driver at a time (the external one first); captures only while something drives the bus
  wire ir_w = ir_write & ~drive;
  wire a_w = a_out & ~drive & ~ir_write;
  wire b_w = b_out & ~drive & ~ir_write & ~a_out;
  wire alu_w = alu_out & ~drive & ~ir_write & ~a_out & ~b_out;
  wire any = drive | ir_write | a_out | b_out | alu_out;
  assign bus = drive ? data : 8'bz;
  instruction_register ir(.clock(clock), .reset(reset), .bus(bus), .read(ir_read & any), .write(ir_w),
                          .clear(1'b0), .instruction(instruction));
  a_b_alu ab(.clock(clock), .bus(bus), .a_in(a_in & any), .a_out(a_w), .a_clear(1'b0), .a_reset(reset), .b_in(b_in & any),
             .b_out(b_w), .b_clear(1'b0), .b_reset(reset), .alu_out(alu_w), .subtract(subtract));
  assign bus_value = any ? bus : 8'h00;
endmodule
"""
add('rtllm_fsm', 'hkust-zhiyao/RTLLM', 'Control/Finite State Machine/fsm/verified_fsm.v', 'verified_fsm', 'CLK', 'RST', 'high-async',
    licence='MIT (RTLLM)', kind='sequence detector FSM (case without default)', rev='41b26896e3')
add('hdlbits_136', 'Wolf-Tungsten/HDLBits-Verilog-Solutions', 'dut/dut_136.v', 'top_module', 'clk', 'reset', 'high-sync',
    licence='not stated', kind='HDLBits FSM solution (case without default)', rev='aa5820b983')
add('hdlbits_137', 'Wolf-Tungsten/HDLBits-Verilog-Solutions', 'dut/dut_137.v', 'top_module', 'clk', 'reset', 'high-sync',
    licence='not stated', kind='HDLBits FSM solution (case without default)', rev='aa5820b983')
add('hdlbits_151', 'Wolf-Tungsten/HDLBits-Verilog-Solutions', 'dut/dut_151.v', 'top_module', 'clk', 'resetn', 'low-sync',
    licence='not stated', kind='HDLBits FSM solution (case without default)', rev='aa5820b983')
add('hdlbits_157', 'Wolf-Tungsten/HDLBits-Verilog-Solutions', 'dut/dut_157.v', 'top_module', 'clk', 'reset', 'high-sync',
    licence='not stated', kind='HDLBits FSM solution (case without default)', rev='aa5820b983')
add('rtllm_freq_divbyfrac', 'hkust-zhiyao/RTLLM', 'Miscellaneous/Frequency divider/freq_divbyfrac/verified_freq_divbyfrac.v', 'freq_divbyfrac', 'clk', 'rst_n', 'low-async',
    licence='MIT (repository LICENSE)', kind='public RTL pass 6 (session 25)', rev='41b26896e3')
add('rtllm_synchronizer', 'hkust-zhiyao/RTLLM', 'Miscellaneous/Others/synchronizer/verified_synchronizer.v', 'verified_synchronizer', 'clk_a', None, None,
    licence='MIT (repository LICENSE)', kind='public RTL pass 6 (session 25)', rev='41b26896e3')
add('aw_uart', 'YosysHQ/yosys', 'tests/asicworld/code_hdl_models_uart.v', 'uart', 'txclk, rxclk', 'reset', 'high-async',
    licence='ISC (repository COPYING); the examples\' folder README: "Borrowed Verilog examples from http://www.asic-world.com/" (the examples\' own licence not stated)', kind='public RTL pass 6 (session 25)', rev='a34d3baae9')
add('aw_clk_div_45', 'YosysHQ/yosys', 'tests/asicworld/code_hdl_models_clk_div_45.v', 'clk_div_45', 'clk_in', 'enable', 'low-sync',
    licence='ISC (repository COPYING); the examples\' folder README: "Borrowed Verilog examples from http://www.asic-world.com/" (the examples\' own licence not stated)', kind='public RTL pass 6 (session 25)', rev='a34d3baae9')
add('aw_rom_using_case', 'YosysHQ/yosys', 'tests/asicworld/code_hdl_models_rom_using_case.v', 'rom_using_case', None, None, None,
    licence='ISC (repository COPYING); the examples\' folder README: "Borrowed Verilog examples from http://www.asic-world.com/" (the examples\' own licence not stated)', kind='public RTL pass 6 (session 25)', rev='a34d3baae9')
add('aw_serial_crc', 'YosysHQ/yosys', 'tests/asicworld/code_hdl_models_serial_crc.v', 'serial_crc_ccitt', 'clk', 'reset', 'high-sync',
    licence='ISC (repository COPYING); the examples\' folder README: "Borrowed Verilog examples from http://www.asic-world.com/" (the examples\' own licence not stated)', kind='public RTL pass 6 (session 25)', rev='a34d3baae9')
add('stffrdhrn_uart_tx', 'stffrdhrn/uart', 'rtl/tx.v', 'tx', 'clk', None, None,
    licence='BSD (readme.md "License: BSD", clause count not stated)', kind='public RTL pass 6 (session 25)', rev='887520c7e4')
add('stffrdhrn_uart_rx', 'stffrdhrn/uart', 'rtl/rx.v', 'rx', 'clk', 'res_n', 'low-async',
    licence='BSD (readme.md "License: BSD", clause count not stated)', kind='public RTL pass 6 (session 25)', rev='887520c7e4')
add('menotti_dec7seg', 'menotti/ld', 'labs/09_pa/dec7seg.v', 'dec7seg', None, None, None,
    licence='MIT (repository LICENSE)', kind='public RTL pass 6 (session 25)', rev='574744f46d')
add('robotichand_debouncer', 'sloboste/roboticHand', 'debouncer.v', 'Button_Debouncer', 'clk', None, None,
    licence='not stated', kind='public RTL pass 6 (session 25)', rev='95bfb60c34')
add('robotichand_pwm', 'sloboste/roboticHand', 'pwm.v', 'pwm', 'PCLK', None, None,
    licence='not stated', kind='public RTL pass 6 (session 25)', rev='95bfb60c34')
add('hdlbits_dualedge', 'gyn/hdlbits', 'p02_Cirucuits/c10_Latches_and_Flip_Flops/s18_dualedge.v', 'top_module', 'clk', None, None,
    licence='MIT (repository LICENSE)', kind='public RTL pass 6 (session 25)', rev='b7a212bbbe')
add('hdlbits_count_clock', 'gyn/hdlbits', 'p02_Cirucuits/c11_Counters/s08_count_clock.v', 'top_module', 'clk', 'reset', 'high-sync',
    licence='MIT (repository LICENSE)', kind='public RTL pass 6 (session 25)', rev='b7a212bbbe')
add('hdlbits_lemmings4', 'gyn/hdlbits', 'p02_Cirucuits/c14_Finite_State_Machines/s13_lemmings4.v', 'top_module', 'clk', 'areset', 'high-async',
    licence='MIT (repository LICENSE)', kind='public RTL pass 6 (session 25)', rev='b7a212bbbe')
add('hdlbits_fsm_serialdata', 'gyn/hdlbits', 'p02_Cirucuits/c14_Finite_State_Machines/s18_fsm_serialdata.v', 'top_module', 'clk', 'reset', 'high-sync',
    licence='MIT (repository LICENSE)', kind='public RTL pass 6 (session 25)', rev='b7a212bbbe')
add('amitav_fifo_sync', 'AmitavMitra/FIFO_verilog', 'FIFO_synchronous/fifo_sync.v', 'fifo_sync', 'clk', 'reset', 'low-async',
    licence='not stated', kind='public RTL pass 6 (session 25)', rev='df061bea48')
add('ysyx_alu', 'Dallous52/ysyx-workbench', 'npc/vsrc/alu.v', 'alu', None, None, None,
    licence='not stated', kind='public RTL pass 6 (session 25)', rev='503a1c1976')
add('projf_xd2', 'projf/projf-explore', 'lib/clock/xd2.sv', 'xd2', 'clk_src, clk_dst', None, None,
    licence='MIT (stated in the file header)', kind='public RTL pass 6 (session 25)', ext='.sv', rev='5aa0c1e549')
add('dincarmon_pwm_gen', 'DinCarmon/FPGA_Capstone_Building_FPGA_Projects_Course', 'week2/ADC/source/pwm_gen.v', 'pwm_gen', 'clk', None, None,
    licence='not stated', kind='public RTL pass 6 (session 25)', rev='045953fe04')
add('aw_arbiter', 'YosysHQ/yosys', 'tests/asicworld/code_hdl_models_arbiter.v', 'arbiter', 'clk', 'rst', 'high-sync',
    licence='ISC (repository COPYING); the examples\' folder README: "Borrowed Verilog examples from http://www.asic-world.com/" (the examples\' own licence not stated)', kind='public RTL pass 6 (session 25)', rev='a34d3baae9')
add('aw_lfsr_updown', 'YosysHQ/yosys', 'tests/asicworld/code_hdl_models_lfsr_updown.v', 'lfsr_updown', 'clk', 'reset', 'high-sync',
    licence='ISC (repository COPYING); the examples\' folder README: "Borrowed Verilog examples from http://www.asic-world.com/" (the examples\' own licence not stated)', kind='public RTL pass 6 (session 25)', rev='a34d3baae9')
add('nl_turnstile', 'nandland/getting-started-with-fpgas', 'chapter08/Turnstile_Example.v', 'Turnstile_Example', 'i_Clk', 'i_Reset', 'high-async',
    licence='MIT', kind='public RTL pass 7 (session 26)', rev='69ba2cbda5')
add('nl_latch', 'nandland/getting-started-with-fpgas', 'chapter04/Latch.v', 'Latch', None, None, None,
    licence='MIT', kind='public RTL pass 7 (session 26)', rev='69ba2cbda5')
add('nl_fifo16', 'nandland/getting-started-with-fpgas', ['chapter06/memory/Verilog/source/FIFO.v', 'chapter06/memory/Verilog/source/RAM_2Port.v'], 'fifo16', 'i_Clk', 'i_Rst_L', 'low-async',
    licence='MIT', kind='public RTL pass 7 (session 26); a small harness around public modules', rev='69ba2cbda5', harness=H['nl_fifo16'], join='lines')
add('nl_smgame', 'nandland/getting-started-with-fpgas', ['chapter08/State_Machine_Project_Verilog/State_Machine_Project_Top.v', 'chapter08/State_Machine_Project_Verilog/State_Machine_Game.v', 'chapter08/State_Machine_Project_Verilog/Binary_To_7Segment.v', 'chapter05/Debounce_Filter.v', 'chapter06/Demux_LFSR_Project_Verilog/LFSR_22.v', 'chapter06/Demux_Count_Project_Verilog/Count_And_Toggle.v'], 'State_Machine_Project_Top', 'i_Clk', None, None,
    licence='MIT', kind='public RTL pass 7 (session 26)', rev='69ba2cbda5', join='cat')
add('nl_spi_master_cs', 'nandland/spi-master', ['Verilog/source/SPI_Master_With_Single_CS.v', 'Verilog/source/SPI_Master.v'], 'SPI_Master_With_Single_CS', 'i_Clk', 'i_Rst_L', 'low-async',
    licence='MIT', kind='public RTL pass 7 (session 26)', rev='1ab581969f', join='lines')
add('af_sync_reset', 'alexforencich/verilog-uart', 'example/Arty/fpga/rtl/sync_reset.v', 'sync_reset', 'clk', 'rst', 'high-async',
    licence='MIT', kind='public RTL pass 7 (session 26)', rev='1b867e53af')
add('af_debounce_switch', 'alexforencich/verilog-uart', 'example/Arty/fpga/rtl/debounce_switch.v', 'debounce_switch', 'clk', 'rst', 'high-async',
    licence='MIT', kind='public RTL pass 7 (session 26)', rev='1b867e53af')
add('af_uart', 'alexforencich/verilog-uart', ['rtl/uart.v', 'rtl/uart_rx.v', 'rtl/uart_tx.v'], 'uart', 'clk', 'rst', 'high-sync',
    licence='MIT', kind='public RTL pass 7 (session 26)', rev='1b867e53af', join='lines')
add('af_arbiter', 'alexforencich/verilog-wishbone', ['rtl/arbiter.v', 'rtl/priority_encoder.v'], 'arbiter', 'clk', 'rst', 'high-sync',
    licence='MIT', kind='public RTL pass 7 (session 26)', rev='d1fa24a0e5', join='lines')
add('af_wb_async_reg', 'alexforencich/verilog-wishbone', 'rtl/wb_async_reg.v', 'wb_async_reg', 'wbm_clk', 'wbm_rst,wbs_rst', 'high-sync',
    licence='MIT', kind='public RTL pass 7 (session 26)', rev='d1fa24a0e5')
add('zip_txuartlite', 'ZipCPU/wbuart32', 'rtl/txuartlite.v', 'txuartlite', 'i_clk', 'i_reset', 'high-sync',
    licence='GPL-3.0-or-later', kind='public RTL pass 7 (session 26)', rev='f43a6b83c3')
add('zip_rxuartlite', 'ZipCPU/wbuart32', 'rtl/rxuartlite.v', 'rxuartlite', 'i_clk', 'i_reset', 'high-sync',
    licence='GPL-3.0-or-later', kind='public RTL pass 7 (session 26)', rev='f43a6b83c3')
add('zip_ufifo', 'ZipCPU/wbuart32', 'rtl/ufifo.v', 'ufifo', 'i_clk', 'i_reset', 'high-sync',
    licence='GPL-3.0-or-later', kind='public RTL pass 7 (session 26)', rev='f43a6b83c3')
add('zip_debouncer', 'ZipCPU/debouncer', 'rtl/debouncer.v', 'debouncer', 'i_clk', None, None,
    licence='GPL-3.0-or-later', kind='public RTL pass 7 (session 26)', rev='d3372955ec')
add('zip_hbdechex', 'ZipCPU/debouncer', 'rtl/hexbus/hbdechex.v', 'hbdechex', 'i_clk', None, None,
    licence='LGPL-3.0-or-later', kind='public RTL pass 7 (session 26)', rev='d3372955ec')
add('ve_gshare', 'NVlabs/verilog-eval', 'dataset_spec-to-rtl/Prob153_gshare_ref.sv', 'RefModule', 'clk', 'areset', 'high-async',
    licence='MIT', kind='public RTL pass 7 (session 26)', ext='.sv', rev='c498220d0a')
add('ve_fancytimer', 'NVlabs/verilog-eval', 'dataset_spec-to-rtl/Prob156_review2015_fancytimer_ref.sv', 'RefModule', 'clk', None, None,
    licence='MIT', kind='public RTL pass 7 (session 26)', ext='.sv', rev='c498220d0a')
add('ve_lemmings4', 'NVlabs/verilog-eval', 'dataset_spec-to-rtl/Prob155_lemmings4_ref.sv', 'RefModule', 'clk', 'areset', 'high-async',
    licence='MIT', kind='public RTL pass 7 (session 26)', ext='.sv', rev='c498220d0a')
add('vtr_mc_rw', 'verilog-to-routing/vtr-verilog-to-routing', 'vtr_flow/benchmarks/verilog/multiclock_reader_writer.v', 'multiclock_reader_writer', 'clock_reader_head', None, None,
    licence='MIT (repository)', kind='public RTL pass 7 (session 26)', rev='5e166de046')
add('vtr_mc_latch', 'verilog-to-routing/vtr-verilog-to-routing', 'vtr_flow/benchmarks/verilog/multiclock_output_and_latch.v', 'multiclock_output_and_latch', 'clock1', None, None,
    licence='MIT (repository)', kind='public RTL pass 7 (session 26)', rev='bcf7729665')
add('is89_s820_raw', 'srinncx/benchmark_circuits', 'iscas89/verilog/s820.v', 's820', None, None, None,
    licence='not stated', kind='public RTL pass 7 (session 26)', rev='617bdb9b1b')
add('is89_s1238', 'srinncx/benchmark_circuits', 'iscas89/bench/s1238.bench', 's1238', 'flip', 'RST', 'high-sync',
    licence='not stated', kind='public RTL pass 7 (session 26)', rev='617bdb9b1b', convert="iscas89_reset")
add('dsd_counterasync4b', 'loboronan07/DSD-Lab', 'Lab_11/counterasync4b.v', 'counterasync4b', 'Clk', 'Reset', 'high-async',
    licence='not stated', kind='public RTL pass 7 (session 26)', rev='fa250c79fa')
add('sig_rom', 'harryknee/Lab2-SigGen', 'task1/rom.sv', 'rom', 'clk', None, None,
    licence='not stated', kind='public RTL pass 7 (session 26)', ext='.sv', rev='ecb36782c7')
add('fft_rom_sinus', 'fulig/TinyFPGA_FFT', 'FFT_stage_8/sim_rom.v', 'ROM_sinus', None, None, None,
    licence='not stated', kind='public RTL pass 7 (session 26)', rev='6d0d31cf05')
add('bsc_counter8', 'B-Lang-org/bsc', 'src/Verilog/Counter.v', 'counter8', 'CLK', 'RST', 'low-sync',
    licence='BSD-3-Clause (repository, not checked per file)', kind='public RTL pass 7 (session 26); a small harness around public modules', rev='03af17e62d', harness=H['bsc_counter8'])
add('bsc_synchandshake', 'B-Lang-org/bsc', 'src/Verilog/SyncHandshake.v', 'SyncHandshake', 'sCLK', 'sRST', 'low-async',
    licence='BSD-3-Clause (repository, not checked per file)', kind='public RTL pass 7 (session 26)', rev='03af17e62d')
add('mcj_hamming', 'mcjtag/hamming_code', 'hdl/hamming_code.v', 'mcj_hamming', None, None, None,
    licence='MIT', kind='public RTL pass 7 (session 26); a small harness around public modules', rev='59470ecf2c', harness=H['mcj_hamming'])
add('cal_8bit_computer', 'CtrlAltLeo/8bit_computer_FPGA', ['computer/eightbit_computer.v', 'computer/program_counter.v', 'computer/instruction_register.v', 'computer/control_logic.v', 'computer/a_b_alu.v', 'computer/output_register.v'], 'computer', 'clock', None, None,
    licence='not stated', kind='public RTL pass 7 (session 26)', rev='9096145078', join='lines')
add('rv64_rf', 'MuhammadMajiid/RV64IMAC', 'SRC_FPGA/riscv_core_rf.sv', 'riscv_core_rf', 'i_rf_clk', None, None,
    licence='not stated', kind='public RTL pass 7 (session 26)', ext='.sv', rev='8ea4af08d2')
add('cal_bus', 'CtrlAltLeo/8bit_computer_FPGA', ['computer/instruction_register.v', 'computer/a_b_alu.v'], 'cal_bus', 'clock', 'reset', 'high-name',
    licence='not stated', kind='public RTL pass 7 (session 26); a small harness around public modules', rev='9096145078', harness=H['cal_bus'], join='lines')
add('oc_ss_pcm', 'ispras/hdl-benchmarks', 'iwls05/opencores/rtl/ss_pcm/pcm_slv_top.v', 'pcm_slv_top', 'clk', 'rst', 'low-sync',
    licence='OpenCores header (free use/redistribution, notice kept; R. Usselmann); repository Apache-2.0', kind='public RTL pass 8 (session 27): PCM slave: serial<->parallel, sampled external bit clock, sync reset', rev='a0c4cfa185')
add('oc_sasc', 'ispras/hdl-benchmarks', ['iwls05/opencores/rtl/sasc/sasc_top.v', 'iwls05/opencores/rtl/sasc/sasc_brg.v', 'iwls05/opencores/rtl/sasc/sasc_fifo4.v'], 'sasc_top', 'clk', 'rst', 'low-sync',
    licence='OpenCores header (R. Usselmann); repository Apache-2.0', kind='public RTL pass 8 (session 27): simple async serial port: baud generator, two 4-deep FIFOs (memory without reset), DPLL, async reset', rev='a0c4cfa185', join='lines')
add('oc_simple_spi', 'ispras/hdl-benchmarks', ['iwls05/opencores/rtl/simple_spi/simple_spi_top.v', 'iwls05/opencores/rtl/simple_spi/fifo4.v'], 'simple_spi_top', 'clk_i', 'rst_i', 'low-async',
    licence='OpenCores header (R. Herveille); repository Apache-2.0', kind='public RTL pass 8 (session 27): Wishbone SPI master with 4-deep FIFOs, translate_off regions', rev='a0c4cfa185', join='lines')
add('oc_usb_phy', 'ispras/hdl-benchmarks', ['iwls05/opencores/rtl/usb_phy/usb_phy.v', 'iwls05/opencores/rtl/usb_phy/usb_rx_phy.v', 'iwls05/opencores/rtl/usb_phy/usb_tx_phy.v'], 'usb_phy', 'clk', 'rst', 'low-sync',
    licence='OpenCores header (R. Usselmann); repository Apache-2.0', kind='public RTL pass 8 (session 27): USB 1.1 PHY: NRZI, bit stuffing, DPLL, three modules', rev='a0c4cfa185', join='lines')
add('q_ts_mike_fsm', 'ispras/hdl-benchmarks', 'quip/ts_mike_fsm/ts_mike_fsm.v', 'ts_mike_fsm', 'clock', None, None,
    licence='QUIP set licence (LGPL where none stated); repository Apache-2.0', kind="public RTL pass 8 (session 27): Moore/Mealy FSM with no reset, 10-bit outputs from 9'b literals (truncated)", rev='a0c4cfa185')
add('q_oc_fcmp', 'ispras/hdl-benchmarks', 'quip/oc_fcmp/oc_fcmp.v', 'oc_fcmp', None, None, None,
    licence='QUIP set licence (LGPL where none stated); repository Apache-2.0', kind='public RTL pass 8 (session 27): combinational IEEE-754 single comparator', rev='a0c4cfa185')
add('q_xbar16', 'ispras/hdl-benchmarks', 'quip/xbar_16x16/xbar_16x16.v', 'xbar_16x16', 'clk', None, None,
    licence='QUIP set licence (LGPL where none stated); repository Apache-2.0', kind='public RTL pass 8 (session 27): 16x16 registered crossbar (variable index)', rev='a0c4cfa185')
add('q_oc_gpio', 'ispras/hdl-benchmarks', ['quip/oc_gpio/defines.v', 'quip/oc_gpio/oc_gpio.v'], 'oc_gpio', 'wb_clk_i', None, None,
    licence='QUIP/OpenCores (LGPL); repository Apache-2.0', kind='public RTL pass 8 (session 27): Wishbone GPIO with an external-clock mux (latch_clk)', rev='a0c4cfa185', join='lines')
add('q_oc_rtc', 'ispras/hdl-benchmarks', ['quip/oc_rtc/defines.v', 'quip/oc_rtc/oc_rtc.v'], 'oc_rtc', 'wb_clk_i', None, None,
    licence='QUIP/OpenCores (LGPL); repository Apache-2.0', kind='public RTL pass 8 (session 27): real-time clock with a muxed clock (lo_clk = en ? div_clk : wb_clk_i)', rev='a0c4cfa185', join='lines')
add('ue_usbf_crc16', 'ultraembedded/cores', 'usb_device/src_v/usbf_crc16.v', 'usbf_crc16', None, None, None,
    licence='GPL-2.0-or-later (file header)', kind='public RTL pass 8 (session 27): combinational USB CRC16 step', rev='cf4d771b5f')
add('ue_usbf_fifo', 'ultraembedded/cores', 'usb_device/src_v/usbf_fifo.v', 'usbf_fifo', 'clk_i', 'rst_i', 'high-async',
    licence='GPL-2.0-or-later (file header)', kind='public RTL pass 8 (session 27): small sync FIFO with a memory', rev='cf4d771b5f')
add('ue_i2s', 'ultraembedded/cores', 'i2s/rtl/i2s.v', 'i2s', 'clk_i', None, None,
    licence='GPL-2.0-or-later (file header)', kind='public RTL pass 8 (session 27): I2S transmitter, two clock domains; source bug: block on audio_rst_i tests rst_i', rev='cf4d771b5f')
add('ue_spdif_core', 'ultraembedded/cores', 'spdif/rtl/spdif_core.v', 'spdif_core', 'clk_i', 'rst_i', 'high-async',
    licence='GPL-2.0-or-later (file header)', kind='public RTL pass 8 (session 27): S/PDIF transmitter: biphase-mark, preambles, parity', rev='cf4d771b5f')
add('ue_uart', 'ultraembedded/cores', 'uart/rtl/uart.v', 'uart', 'clk_i', 'rst_i', 'high-async',
    licence='GPL-2.0-or-later (file header)', kind='public RTL pass 8 (session 27): UART TX/RX core with divisor', rev='cf4d771b5f')
add('ue_usbf_sie_tx', 'ultraembedded/cores', ['usb_device/src_v/usbf_defs.v', 'usb_device/src_v/usbf_crc16.v', 'usb_device/src_v/usbf_sie_tx.v'], 'usbf_sie_tx', 'clk_i', 'rst_i', 'high-async',
    licence='GPL-2.0-or-later (file header)', kind='public RTL pass 8 (session 27): USB SIE transmit FSM with CRC16 (3 files)', rev='cf4d771b5f', join='lines')
add('sd_mac_crc32', 'freecores/srdydrdy_lib', 'examples/bridge/rtl/mac_crc32.v', 'mac_crc32', 'clk', 'clear', 'high-sync',
    licence='not stated (file); library blocks are public domain', kind='public RTL pass 8 (session 27): 8-bit parallel CRC32 by an unrolled for loop', rev='a0172dd47a')
add('sd_iofull', 'freecores/srdydrdy_lib', ['rtl/verilog/closure/sd_input.v', 'rtl/verilog/closure/sd_output.v', 'rtl/verilog/closure/sd_iofull.v'], 'sd_iofull', 'clk', 'reset', 'high-async',
    licence='public domain (file header)', kind='public RTL pass 8 (session 27): srdy/drdy pipeline stage; an implicit net (i_srdy)', rev='a0172dd47a', join='lines')
add('zc_wbwatchdog', 'ZipCPU/zipcpu', 'rtl/peripherals/wbwatchdog.v', 'wbwatchdog', 'i_clk', 'i_reset', 'high-sync',
    licence='GPL-3.0-or-later (file header)', kind='public RTL pass 8 (session 27): Wishbone watchdog timer', rev='42606d2d6e')
add('zc_zipcounter', 'ZipCPU/zipcpu', 'rtl/peripherals/zipcounter.v', 'zipcounter', 'i_clk', 'i_reset', 'high-sync',
    licence='GPL-3.0-or-later (file header)', kind='public RTL pass 8 (session 27): Wishbone counter with interrupt', rev='42606d2d6e')
add('zc_ziptimer', 'ZipCPU/zipcpu', 'rtl/peripherals/ziptimer.v', 'ziptimer', 'i_clk', 'i_reset', 'high-sync',
    licence='GPL-3.0-or-later (file header)', kind='public RTL pass 8 (session 27): reloadable Wishbone timer', rev='42606d2d6e')
add('zc_skidbuffer', 'ZipCPU/zipcpu', 'rtl/ex/skidbuffer.v', 'skidbuffer', 'i_clk', 'i_reset', 'high-sync',
    licence='GPL-3.0-or-later (file header)', kind='public RTL pass 8 (session 27): skid buffer, OPT_OUTREG, initial values', rev='42606d2d6e')
add('zc_icontrol', 'ZipCPU/zipcpu', 'rtl/peripherals/icontrol.v', 'icontrol', 'i_clk', 'i_reset', 'high-sync',
    licence='GPL-3.0-or-later (file header)', kind='public RTL pass 8 (session 27): interrupt controller', rev='42606d2d6e')
add('zc_slowmpy', 'ZipCPU/zipcpu', 'rtl/core/slowmpy.v', 'slowmpy', 'i_clk', 'i_reset', 'high-sync',
    licence='GPL-3.0-or-later (file header)', kind='public RTL pass 8 (session 27): 33x33 signed shift-add multiplier', rev='42606d2d6e')
add('ve_circuit8', 'NVlabs/verilog-eval', 'dataset_spec-to-rtl/Prob145_circuit8_ref.sv', 'RefModule', 'clock', None, None,
    licence='MIT (repository)', kind='public RTL pass 8 (session 27): negedge flop + level latch on the clock (p = a while clock)', ext='.sv', rev='c498220d0a')
add('ve_dff8p', 'NVlabs/verilog-eval', 'dataset_spec-to-rtl/Prob046_dff8p_ref.sv', 'RefModule', 'clk', 'reset', 'high-sync',
    licence='MIT (repository)', kind="public RTL pass 8 (session 27): negedge register, sync reset to 8'h34 (inverted latches)", ext='.sv', rev='c498220d0a')
add('ve_gatesv', 'NVlabs/verilog-eval', 'dataset_spec-to-rtl/Prob094_gatesv_ref.sv', 'RefModule', None, None, None,
    licence='MIT (repository)', kind="public RTL pass 8 (session 27): combinational; two output bits assigned 1'bx", ext='.sv', rev='c498220d0a')
add('ve_ps2data', 'NVlabs/verilog-eval', 'dataset_spec-to-rtl/Prob154_fsm_ps2data_ref.sv', 'RefModule', 'clk', 'reset', 'high-sync',
    licence='MIT (repository)', kind="public RTL pass 8 (session 27): FSM + shift register; output 'x when not done", ext='.sv', rev='c498220d0a')
add('ve_casez', 'NVlabs/verilog-eval', 'dataset_spec-to-rtl/Prob071_always_casez_ref.sv', 'RefModule', None, None, None,
    licence='MIT (repository)', kind='public RTL pass 8 (session 27): casez priority encoder with the default listed first', ext='.sv', rev='c498220d0a')
add('ve_q8', 'NVlabs/verilog-eval', 'dataset_spec-to-rtl/Prob129_ece241_2013_q8_ref.sv', 'RefModule', 'clk', 'aresetn', 'low-async',
    licence='MIT (repository)', kind="public RTL pass 8 (session 27): Mealy FSM, async active-low reset, default 'x", ext='.sv', rev='c498220d0a')
add('ve_fsm_hdlc', 'NVlabs/verilog-eval', 'dataset_spec-to-rtl/Prob140_fsm_hdlc_ref.sv', 'RefModule', 'clk', 'reset', 'high-sync',
    licence='MIT (repository)', kind='public RTL pass 8 (session 27): HDLC bit-stuffing FSM', ext='.sv', rev='c498220d0a')
add('vtr_mc_sep_latch', 'verilog-to-routing/vtr-verilog-to-routing', 'vtr_flow/benchmarks/verilog/multiclock_separate_and_latch.v', 'multiclock_separate_and_latch', 'clocks', None, None,
    licence='MIT (repository)', kind='public RTL pass 8 (session 27): two clocks; procedural assignment to a net output', rev='9719c44105')
add('af_axis_srl_fifo', 'alexforencich/verilog-axis', 'rtl/axis_srl_fifo.v', 'axis_srl_fifo', 'clk', 'rst', 'high-sync',
    licence='MIT (file header)', kind='public RTL pass 8 (session 27): AXI-Stream SRL FIFO (16 deep shift registers)', rev='48ff7a7e2e')
add('af_axis_frame_len', 'alexforencich/verilog-axis', 'rtl/axis_frame_len.v', 'axis_frame_len', 'clk', 'rst', 'high-sync',
    licence='MIT (file header)', kind='public RTL pass 8 (session 27): AXI-Stream frame length counter', rev='48ff7a7e2e')
add('af_axis_cobs_decode', 'alexforencich/verilog-axis', 'rtl/axis_cobs_decode.v', 'axis_cobs_decode', 'clk', 'rst', 'high-sync',
    licence='MIT (file header)', kind='public RTL pass 8 (session 27): COBS decoder FSM', rev='48ff7a7e2e')
add('af_axis_rate_limit', 'alexforencich/verilog-axis', 'rtl/axis_rate_limit.v', 'axis_rate_limit', 'clk', 'rst', 'high-sync',
    licence='MIT (file header)', kind='public RTL pass 8 (session 27): AXI-Stream rate limiter (accumulator)', rev='48ff7a7e2e')
add('af_lfsr_crc', 'alexforencich/verilog-lfsr', ['rtl/lfsr.v', 'rtl/lfsr_crc.v'], 'lfsr_crc', 'clk', None, None,
    licence='MIT (file header)', kind="public RTL pass 8 (session 27): CRC-32 via lfsr.v's constant function lfsr_mask()", rev='c1f86d0367', join='lines')
add('af_lfsr_prbs_check', 'alexforencich/verilog-lfsr', ['rtl/lfsr.v', 'rtl/lfsr_prbs_check.v'], 'lfsr_prbs_check', 'clk', None, None,
    licence='MIT (file header)', kind='public RTL pass 8 (session 27): PRBS31 checker via lfsr.v', rev='c1f86d0367', join='lines')
add('is24_div_4s_8s', 'ispras/hdl-benchmarks', 'ispras24/comb/div/div_4s_8s.v', 'div_4s_8s', None, None, None,
    licence='Apache-2.0 (repository)', kind='public RTL pass 8 (session 27): signed division (x on divide by zero)', rev='a0c4cfa185')
add('is24_mod_7s_3s', 'ispras/hdl-benchmarks', 'ispras24/comb/mod/mod_7s_3s.v', 'mod_7s_3s', None, None, None,
    licence='Apache-2.0 (repository)', kind='public RTL pass 8 (session 27): signed modulus (x on zero)', rev='a0c4cfa185')
add('is24_pow_6_4', 'ispras/hdl-benchmarks', 'ispras24/comb/pow/pow_6_4.v', 'pow_6_4', None, None, None,
    licence='Apache-2.0 (repository)', kind='public RTL pass 8 (session 27): a ** b with variable exponent, 24-bit result', rev='a0c4cfa185')
add('is24_dffsr', 'ispras/hdl-benchmarks', 'ispras24/seq/dffsr.v', 'dffsr', 'CLK', None, None,
    licence='Apache-2.0 (repository)', kind='public RTL pass 8 (session 27): flip-flop with async set and reset, generate per bit', rev='a0c4cfa185')
add('is24_aldff', 'ispras/hdl-benchmarks', 'ispras24/seq/aldff.v', 'aldff', 'CLK', None, None,
    licence='Apache-2.0 (repository)', kind='public RTL pass 8 (session 27): flip-flop with asynchronous load', rev='a0c4cfa185')
add('is24_dlatchsr', 'ispras/hdl-benchmarks', 'ispras24/seq/dlatchsr.v', 'dlatchsr', None, None, None,
    licence='Apache-2.0 (repository)', kind='public RTL pass 8 (session 27): latch with set/reset, no clock', rev='a0c4cfa185')
add('is85_c432', 'ispras/hdl-benchmarks', 'iscas85/verilog/c432.v', 'c432', None, None, None,
    licence='not stated; repository Apache-2.0', kind='public RTL pass 8 (session 27): ISCAS-85 gate-level netlist (primitives)', rev='a0c4cfa185')

for d in D:
    rev, harness, convert, join = d.pop("rev"), d.pop("harness"), d.pop("convert"), d.pop("join")
    texts = [show(d["repo"], p, rev) for p in d["paths"]]
    if len(texts) > 1:   # inline: one file per design; `include of the bundled files dropped
        texts = [re.sub(r'^\s*`include\s+"[^"]*"\s*$', "", t, flags=re.M) for t in texts]
    if join == "cat":
        text = "".join(texts)
    else:
        text = ("\n" if join == "blank" else "").join(t if t.endswith("\n") else t + "\n" for t in texts)
    if any('`include "timescale.v"' in t for t in texts):
        text = text.replace('`include "timescale.v"', "")
    if convert == "iscas89_reset":   # the .bench netlist as scripts/iscas89_reset.py writes it (reset RST, STATE port)
        import sys; sys.path.insert(0, str(Path(__file__).resolve().parent))
        from iscas89_reset import comment_lines, bench_to_verilog, TRANSFORM_NOTE
        top = d["paths"][0].rsplit("/", 1)[-1].split(".")[0]
        text = "\n".join(comment_lines(text, "#")) + "\n" + TRANSFORM_NOTE + "\n" + bench_to_verilog(text, top)
        d["note"] = (d["note"] + " " if d["note"] else "") + "converted by scripts/iscas89_reset.py"
    if harness:
        text += ("" if text.endswith("\n") else "\n") + harness
        d["note"] = (d["note"] + " " if d["note"] else "") + f"+ {len(harness.splitlines())}-line harness (module {d['top']}) appended;"
    folder = OUT / d["name"]; folder.mkdir(parents=True, exist_ok=True)
    fname = d["name"] + d.pop("ext")
    (folder / fname).write_text(text)
    if len(d["paths"]) > 1 or '`include' in "".join(show(d["repo"], p, rev) for p in d["paths"]):
        d["note"] = (d["note"] + " " if d["note"] else "") + "files concatenated in the order listed; `include lines of bundled files removed"
    d.update(file=f"{d['name']}/{fname}", commit=commit(d["repo"], rev), sha256=hashlib.sha256(text.encode()).hexdigest())
(OUT / "manifest.json").write_text(json.dumps({"suite": "public RTL for mech2spice issue 34", "designs": D}, indent=1) + "\n")
print(len(D), "designs")
