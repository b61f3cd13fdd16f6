#pragma once
// Fault injection into the simulated site (--sim --sim-faults DIR), for the
// hardware-in-the-loop tests and drills: a file in DIR stands for a fault of
// the simulated hardware, so a test process can break the daemon's hardware
// from outside, as a real cabinet's hardware would break.
//
//   tool_jam        the LST's output cannot turn while the file exists
//   ft_fault        the F/T sensor reports a sensor fault while it exists
//   oru_stuck       the ORU stays fastened in its slot while it exists
//   video_silent    the video switch reads requests and never answers while it exists
//   drive_emcy_J    joint J (1-based) faults once, with EMCY code = the file's
//                   text in hex (default 2310, over-current), each time the
//                   file appears
//   drive_silent_J  joint J's drive stops sending its heartbeat while it exists
//   drive_reboot_J  joint J's drive reboots once (a brown-out: boot-up message,
//                   pre-operational, its object dictionary back to its defaults,
//                   PDO mapping lost), each time the file appears
//   bus_loss_B      bus B (0-based, config order) loses every frame both ways
//                   while it exists (CanSimulator::set_impairment, loss 1.0)
//   estop_circuit   the cabinet's E-stop circuit is open while it exists: every
//                   drive's safe torque off input is active (no torque; the
//                   statusword carries remote.yaml's sto_status_bit)
//
// And one output, the simulated drives' own record (not the master's view of
// them), for tests that check no motion happened that was not commanded:
//   drive_record    written each poll (temp file + rename). Line 1: "seq marks"
//                   then the simulated joint angles (rad), then per joint the
//                   lowest and the highest angle since the last mark: 2 + 3 x 7
//                   numbers. Line 2: "power" then per joint its CiA 402 state
//                   as the drive itself holds it (snake case, as `foresight
//                   status --json`), 1 if its power stage is energised else 0,
//                   and the states it was in since the last mark (a bit mask,
//                   bit = the state's CiA 402 value: 0 not ready to switch on
//                   .. 4 operation enabled, 5 quick stop active .. 7 fault)
//   drive_record_mark  create it to start a new envelope (the watcher deletes
//                   it and counts the mark in `marks`)
//
// A thread polls DIR every 20 ms. Not on a real cabinet (the option needs --sim).

#include <atomic>
#include <cstdint>
#include <string>
#include <thread>
#include <vector>

#include "foresight/daemon/site.hpp"

namespace foresight::daemon {

class SimFaultWatcher {
 public:
  /// Starts polling `dir` (created if missing). `site` must be simulated and outlive the watcher.
  SimFaultWatcher(Site& site, std::string dir);
  ~SimFaultWatcher();
  SimFaultWatcher(const SimFaultWatcher&) = delete;
  SimFaultWatcher& operator=(const SimFaultWatcher&) = delete;

 private:
  void run();
  Site& site_;
  std::string dir_;
  void write_record();
  std::vector<bool> emcy_present_;
  std::vector<bool> silent_present_;
  std::vector<bool> reboot_present_;
  std::vector<bool> bus_loss_present_;
  std::vector<double> q_, lo_, hi_;
  std::uint64_t seq_ = 0, marks_ = 0;
  bool jam_ = false, ft_fault_ = false, stuck_ = false, video_silent_ = false, sto_ = false;
  std::atomic<bool> quit_{false};
  std::thread thread_;
};

}  // namespace foresight::daemon
