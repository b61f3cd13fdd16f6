#pragma once
// The LST (Lightweight Servicing Tool) Modbus register map: the one contract
// between the tool client (lst_tool.hpp) and the tool (the real controller, or
// the simulator in remote_site/sim/lst_server.hpp). docs/hardware.md has the
// same table for people; this header is the table for the compiler.
//
// Addresses are 0-based protocol addresses (what goes on the wire), per table:
//
// Coils (read/write bits; FC 01 read, FC 05 write one, FC 15 write many)
//   0 RUN          1 = turn the socket at SPEED_CMD in DIRECTION until the
//                  torque limit is reached, a fault, or RUN = 0. The tool
//                  clears RUN itself when it stops on its own.
//   1 DIRECTION    0 = tighten (clockwise seen from behind the tool), 1 = loosen
//   2 LATCH        1 = close the latch jaws (grip the ORU), 0 = open (unlatch)
//   3 FAULT_RESET  write 1 to clear the fault word (self-clearing, reads 0)
//   4 TURNS_RESET  write 1 to zero the turns counter (self-clearing, reads 0)
//
// Discrete inputs (read-only bits; FC 02); the same bits as STATUS below
//   0 READY  1 RUNNING  2 LATCHED  3 UNLATCHED  4 TORQUE_REACHED  5 FAULT
//
// Holding registers (read/write 16-bit; FC 03 read, FC 06 write one, FC 16 many)
//   0 SPEED_CMD         uint16, 0.01 rad/s per count, socket speed magnitude,
//                       0 .. max_speed (tool's limit; above it: exception 03)
//   1 TORQUE_LIMIT      uint16, 0.01 N*m per count: the tool stops (and sets
//                       TORQUE_REACHED) when the output torque reaches it;
//                       0 .. max_torque (above it: exception 03)
//
// Input registers (read-only 16-bit; FC 04). 0..7 are read in one request.
//   0 STATUS            bit field, kStatus* below
//   1 FAULT             bit field, kFault* below (latched until FAULT_RESET)
//   2 TURNS_HI          int32 turns counter, 0.001 turn per count, high word
//   3 TURNS_LO          ... low word. Positive = tightening (clockwise)
//   4 TORQUE            int16, 0.01 N*m per count, output torque, + = clockwise
//   5 SPEED             int16, 0.01 rad/s per count, socket speed, + = clockwise
//   6 ALIVE             uint16, +1 every 10 ms of the tool's own clock (wraps):
//                       a frozen tool shows a frozen counter
//   7 PEAK_TORQUE       int16, 0.01 N*m per count: the output torque of largest
//                       magnitude during the present or last run (the final
//                       torque of a tightening; reset when RUN rises)
//
// Any other address is answered with exception 02 (illegal data address).

#include <cmath>
#include <cstdint>

namespace foresight::hw::lst {

// ---- coils -------------------------------------------------------------------
inline constexpr int kCoilRun = 0;
inline constexpr int kCoilDirection = 1;
inline constexpr int kCoilLatch = 2;
inline constexpr int kCoilFaultReset = 3;
inline constexpr int kCoilTurnsReset = 4;
inline constexpr int kNumCoils = 5;

/// DIRECTION coil values.
inline constexpr std::uint8_t kDirectionTighten = 0;
inline constexpr std::uint8_t kDirectionLoosen = 1;

// ---- discrete inputs (bit index = STATUS bit) ----------------------------------
inline constexpr int kNumDiscreteInputs = 6;

// ---- holding registers -----------------------------------------------------------
inline constexpr int kHoldSpeedCmd = 0;
inline constexpr int kHoldTorqueLimit = 1;
inline constexpr int kNumHolding = 2;

// ---- input registers ---------------------------------------------------------------
inline constexpr int kInStatus = 0;
inline constexpr int kInFault = 1;
inline constexpr int kInTurnsHi = 2;
inline constexpr int kInTurnsLo = 3;
inline constexpr int kInTorque = 4;
inline constexpr int kInSpeed = 5;
inline constexpr int kInAlive = 6;
inline constexpr int kInPeakTorque = 7;
inline constexpr int kNumInput = 8;

// ---- STATUS bits (input register 0; discrete inputs 0..5) -----------------------
inline constexpr std::uint16_t kStatusReady = 1u << 0;          ///< powered, no fault
inline constexpr std::uint16_t kStatusRunning = 1u << 1;        ///< socket turning under RUN
inline constexpr std::uint16_t kStatusLatched = 1u << 2;        ///< jaws closed (end switch)
inline constexpr std::uint16_t kStatusUnlatched = 1u << 3;      ///< jaws open (end switch)
inline constexpr std::uint16_t kStatusTorqueReached = 1u << 4;  ///< last run stopped at the torque limit
inline constexpr std::uint16_t kStatusFault = 1u << 5;          ///< FAULT word is non-zero

// ---- FAULT bits (input register 1) ------------------------------------------------
/// The output did not turn for the stall time while RUN was set and the output
/// torque stayed below the limit (gear train or socket jammed). The tool stops.
inline constexpr std::uint16_t kFaultJam = 1u << 0;
/// The latch did not reach its commanded end position within its travel time.
inline constexpr std::uint16_t kFaultLatch = 1u << 1;

// ---- scaling -----------------------------------------------------------------------
inline constexpr double kSpeedRadSPerCount = 0.01;
inline constexpr double kTorqueNmPerCount = 0.01;
inline constexpr double kTurnsPerCount = 0.001;
inline constexpr double kAlivePeriodS = 0.01;

/// The turns counter's value for `turns` turned: the whole counts passed,
/// truncated toward zero as an incremental counter counts. A count of
/// -2000 therefore means at least 2 turns were made: rounding reported
/// -2.000 at -1.9996 turns, the tool stopped there and the simulated screw
/// kept 0.0004 turns of thread (LstServer.LoosenAndTightenTaskSteps under
/// ASan).
inline std::int32_t turns_to_counts(double turns) {
  return static_cast<std::int32_t>(std::trunc(turns / kTurnsPerCount));
}

}  // namespace foresight::hw::lst
