// The real-time cycle (cycle_read + cycle_write) must not touch the heap,
// also when it reports faults. This binary replaces the global operator
// new/delete and counts allocations made by the test thread only (the
// simulator thread allocates freely; it is not real-time code).

#include <atomic>
#include <cstdlib>
#include <new>

#include "sim_fixture.hpp"

namespace {
thread_local bool g_counting = false;
std::atomic<long> g_allocations{0};

void* counted_alloc(std::size_t n) {
  if (g_counting) g_allocations.fetch_add(1, std::memory_order_relaxed);
  if (void* p = std::malloc(n ? n : 1)) return p;
  throw std::bad_alloc();
}
}  // namespace

void* operator new(std::size_t n) { return counted_alloc(n); }
void* operator new[](std::size_t n) { return counted_alloc(n); }
void* operator new(std::size_t n, const std::nothrow_t&) noexcept {
  if (g_counting) g_allocations.fetch_add(1, std::memory_order_relaxed);
  return std::malloc(n ? n : 1);
}
void* operator new[](std::size_t n, const std::nothrow_t&) noexcept {
  if (g_counting) g_allocations.fetch_add(1, std::memory_order_relaxed);
  return std::malloc(n ? n : 1);
}
void operator delete(void* p) noexcept { std::free(p); }
void operator delete[](void* p) noexcept { std::free(p); }
void operator delete(void* p, std::size_t) noexcept { std::free(p); }
void operator delete[](void* p, std::size_t) noexcept { std::free(p); }

using namespace foresight;
using namespace foresight::test;

TEST(RtAlloc, CounterWorks) {
  g_allocations = 0;
  g_counting = true;
  auto* v = new std::vector<int>(100);
  g_counting = false;
  delete v;
  EXPECT_GE(g_allocations.load(), 2);  // the guard can fail
}

TEST(RtAlloc, CycleDoesNotAllocateEvenWhileReportingFaults) {
  SimRig rig(project_config());
  rig.bring_up();
  rig.drives->request_tare(5);
  long frames = 0;
  int events = 0;
  g_allocations = 0;
  for (int i = 0; i < 300; ++i) {
    // faults injected from the far end while the cycle runs
    if (i == 100) rig.sim->inject(0, hw::make_frame(0x181, {1, 2}));   // malformed TPDO
    if (i == 120) rig.sim->inject(1, hw::make_frame(0x555, {1}));      // unknown COB-ID
    if (i == 150) rig.sim->drive(3).inject_fault(0x4310);              // EMCY + Fault
    if (i == 200) rig.sim->drive(5).silence_heartbeat(true);           // heartbeat lost
    if (i == 250) {
      rig.targets.position_rad[0] = std::nan("");                      // invalid target
      rig.drives->request_quick_stop();
    }
    std::this_thread::sleep_until(rig.deadline);
    rig.deadline += std::chrono::milliseconds(2);
    g_counting = true;
    const CycleStatus s = rig.drives->cycle_read(rig.fb, rig.ft);
    rig.drives->cycle_write(rig.targets);
    g_counting = false;
    frames += s.frames_received;
    events += s.event_count;
  }
  EXPECT_EQ(g_allocations.load(), 0);
  EXPECT_GT(frames, 300 * 9);  // the cycle did real work: 7 TPDOs + 2 F/T frames a cycle
  EXPECT_GE(events, 5);        // and reported the injected faults
}
