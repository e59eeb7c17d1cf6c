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
def show(repo, path):
    return subprocess.run(["git", "-C", str(M / repo.replace("/", "+") / "repo"), "show", f"HEAD:{path}"],
                          capture_output=True, check=True).stdout.decode("utf-8", "replace")
def commit(repo):
    return subprocess.run(["git", "-C", str(M / repo.replace("/", "+") / "repo"), "rev-parse", "HEAD"],
                          capture_output=True, text=True, check=True).stdout.strip()
D = []
def add(name, repo, paths, top, clock=None, reset=None, level=None, licence="not stated", kind="", ext=".v", note=""):
    D.append(dict(name=name, repo=repo, paths=paths if isinstance(paths, list) else [paths], top=top, clock=clock,
                  reset=reset, reset_level=level, licence=licence, kind=kind, ext=ext, note=note))
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

for d in D:
    texts = [show(d["repo"], p) for p in d["paths"]]
    if len(texts) > 1:   # inline: one file per design; `include of the bundled files dropped
        texts = [re.sub(r'^\s*`include\s+"[^"]*"\s*$', "", t, flags=re.M) for t in texts]
    text = "\n".join(t if t.endswith("\n") else t + "\n" for t in texts)
    if any('`include "timescale.v"' in t for t in texts):
        text = text.replace('`include "timescale.v"', "")
    folder = OUT / d["name"]; folder.mkdir(parents=True, exist_ok=True)
    fname = d["name"] + d.pop("ext")
    (folder / fname).write_text(text)
    if len(d["paths"]) > 1 or '`include' in "".join(show(d["repo"], p) for p in d["paths"]):
        d["note"] = (d["note"] + " " if d["note"] else "") + "files concatenated in the order listed; `include lines of bundled files removed"
    d.update(file=f"{d['name']}/{fname}", commit=commit(d["repo"]), sha256=hashlib.sha256(text.encode()).hexdigest())
(OUT / "manifest.json").write_text(json.dumps({"suite": "public RTL for mech2spice issue 34", "designs": D}, indent=1) + "\n")
print(len(D), "designs")
