// The real-time cycle (cycle_read + send_sync + cycle_write) must not touch the heap,
// also when it reports faults. Counted through both operator new and malloc
// (foresight/test/allocation_counter.hpp), on the test thread only (the
// simulator thread allocates freely; it is not real-time code).

#include <cmath>
#include <cstdlib>
#include <vector>

#include "foresight/test/allocation_counter.hpp"
#include "sim_fixture.hpp"

using namespace foresight;
using namespace foresight::test;

TEST(RtAlloc, CounterWorks) {
  long seen = 0;
  {
    AllocationCounter counter;
    auto* v = new std::vector<int>(100);  // operator new, twice
    void* p = std::malloc(64);            // and the C allocator
    seen = counter.count();
    std::free(p);
    delete v;
  }
  EXPECT_EQ(seen, 3);  // the guard can fail
}

TEST(RtAlloc, CycleDoesNotAllocateEvenWhileReportingFaults) {
  SimRig rig(project_config());
  rig.bring_up();
  rig.drives->request_tare(5);
  long frames = 0;
  int events = 0;
  AllocationCounter counter;
  counter.pause();
  for (int i = 0; i < 300; ++i) {
    // faults injected from the far end while the cycle runs
    if (i == 20) {  // late frames on arm_a (stale TPDOs behind the looped-back SYNC), loss on arm_b
      sim::BusImpairment late;
      late.delay_s = 0.007;
      rig.sim->set_impairment(0, late);
      sim::BusImpairment lossy;
      lossy.loss = 0.05;
      rig.sim->set_impairment(1, lossy);
    }
    if (i == 80) rig.sim->set_impairment(0, sim::BusImpairment{});
    if (i == 90) rig.sim->inject_error_passive(0);                     // error frame
    if (i == 100) rig.sim->inject(0, hw::make_frame(0x181, {1, 2}));   // malformed TPDO
    if (i == 120) rig.sim->inject(1, hw::make_frame(0x555, {1}));      // unknown COB-ID
    if (i == 150) rig.sim->drive(3).inject_fault(0x4310);              // EMCY + Fault
    if (i == 200) rig.sim->drive(5).silence_heartbeat(true);           // heartbeat lost
    if (i == 250) {
      rig.targets.position_rad[0] = std::nan("");                      // invalid target
      rig.drives->request_quick_stop();
    }
    if (i == 280) rig.drives->request_power_off();                     // category 0: Disable Voltage to all
    std::this_thread::sleep_until(rig.deadline);
    rig.deadline += std::chrono::milliseconds(2);
    counter.resume();
    const CycleStatus s = rig.drives->cycle_read(rig.fb, rig.ft);
    rig.drives->send_sync();  // the control loop's order: SYNC at the wake-up
    rig.drives->cycle_write(rig.targets);
    counter.pause();
    frames += s.frames_received;
    events += s.event_count;
  }
  EXPECT_EQ(counter.count(), 0);
  EXPECT_GT(frames, 300 * 9);  // the cycle did real work: 7 TPDOs + 2 F/T frames a cycle
  EXPECT_GE(events, 5);        // and reported the injected faults
  EXPECT_GT(rig.drives->stale_tpdos(0), 0u);  // the stale-TPDO path ran inside the counted cycles
}
