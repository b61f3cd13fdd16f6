// The real-time half of the kinematics contract: with a pre-built workspace,
// forward_kinematics, jacobian and gravity_torques never touch the heap.
// This binary replaces global operator new/delete AND interposes the C
// allocator (malloc, calloc, realloc, the aligned forms; Eigen and KDL's
// Eigen-backed arrays allocate through malloc, not operator new) with counting
// versions that forward to glibc's __libc_* functions. The counter is armed
// only around the calls under test. (glibc-specific, like the project.)

#include <gtest/gtest.h>

#include <atomic>
#include <cerrno>
#include <cmath>
#include <cstdlib>
#include <new>
#include <random>
#include <vector>

#include "foresight/common/kinematics.hpp"
#include "foresight/common/robot_model.hpp"

extern "C" {
void* __libc_malloc(std::size_t);
void* __libc_calloc(std::size_t, std::size_t);
void* __libc_realloc(void*, std::size_t);
void* __libc_memalign(std::size_t, std::size_t);
void __libc_free(void*);
}

namespace {
std::atomic<bool> g_counting{false};
std::atomic<long> g_allocations{0};
inline void count() {
  if (g_counting.load(std::memory_order_relaxed)) g_allocations.fetch_add(1, std::memory_order_relaxed);
}
void* checked(void* p) {
  if (p == nullptr) throw std::bad_alloc();
  return p;
}
}  // namespace

// ---- the C allocator ----
extern "C" {
void* malloc(std::size_t n) {
  count();
  return __libc_malloc(n);
}
void* calloc(std::size_t n, std::size_t size) {
  count();
  return __libc_calloc(n, size);
}
void* realloc(void* p, std::size_t n) {
  count();
  return __libc_realloc(p, n);
}
void* memalign(std::size_t a, std::size_t n) {
  count();
  return __libc_memalign(a, n);
}
void* aligned_alloc(std::size_t a, std::size_t n) {
  count();
  return __libc_memalign(a, n);
}
int posix_memalign(void** out, std::size_t a, std::size_t n) {
  count();
  void* p = __libc_memalign(a, n);
  if (p == nullptr) return ENOMEM;
  *out = p;
  return 0;
}
void free(void* p) { __libc_free(p); }
}

// ---- C++ operator new/delete ----
void* operator new(std::size_t n) {
  count();
  return checked(__libc_malloc(n == 0 ? 1 : n));
}
void* operator new[](std::size_t n) {
  count();
  return checked(__libc_malloc(n == 0 ? 1 : n));
}
void* operator new(std::size_t n, const std::nothrow_t&) noexcept {
  count();
  return __libc_malloc(n == 0 ? 1 : n);
}
void* operator new[](std::size_t n, const std::nothrow_t&) noexcept {
  count();
  return __libc_malloc(n == 0 ? 1 : n);
}
void* operator new(std::size_t n, std::align_val_t a) {
  count();
  return checked(__libc_memalign(static_cast<std::size_t>(a), n == 0 ? 1 : n));
}
void* operator new[](std::size_t n, std::align_val_t a) {
  count();
  return checked(__libc_memalign(static_cast<std::size_t>(a), n == 0 ? 1 : n));
}
void operator delete(void* p) noexcept { __libc_free(p); }
void operator delete[](void* p) noexcept { __libc_free(p); }
void operator delete(void* p, std::size_t) noexcept { __libc_free(p); }
void operator delete[](void* p, std::size_t) noexcept { __libc_free(p); }
void operator delete(void* p, std::align_val_t) noexcept { __libc_free(p); }
void operator delete[](void* p, std::align_val_t) noexcept { __libc_free(p); }
void operator delete(void* p, std::size_t, std::align_val_t) noexcept { __libc_free(p); }
void operator delete[](void* p, std::size_t, std::align_val_t) noexcept { __libc_free(p); }

using namespace foresight;

namespace {

/// Counts allocations made while it is alive (this thread's calls only run then).
class AllocationCounter {
 public:
  AllocationCounter() {
    g_allocations = 0;
    g_counting = true;
  }
  ~AllocationCounter() { g_counting = false; }
  long count() const { return g_allocations.load(); }
};

}  // namespace

TEST(KinematicsNoAlloc, CounterSeesAllocations) {
  // The guard itself must work, or the tests below prove nothing.
  long seen = 0;
  {
    AllocationCounter counter;
    auto* v = new std::vector<double>(100);  // operator new, twice
    seen = counter.count();
    delete v;
  }
  EXPECT_EQ(seen, 2);
  {
    AllocationCounter counter;
    Eigen::VectorXd x(50);  // Eigen: malloc
    x.setZero();
    seen = counter.count();
  }
  EXPECT_EQ(seen, 1);
}

TEST(KinematicsNoAlloc, FkJacobianGravityDoNotAllocate) {
  const RobotModel model = RobotModel::from_file(FORESIGHT_CONFIG_DIR "/robot.urdf");
  KinematicsWorkspace ws(model);
  const int n = model.dof();
  // Inputs prepared before counting.
  std::mt19937 rng(5);
  std::vector<Eigen::VectorXd> qs;
  for (int k = 0; k < 1000; ++k) {
    Eigen::VectorXd q(n);
    for (int i = 0; i < n; ++i) {
      std::uniform_real_distribution<double> u(model.limits()[i].lower_rad, model.limits()[i].upper_rad);
      q[i] = u(rng);
    }
    qs.push_back(q);
  }
  Eigen::Matrix<double, 6, Eigen::Dynamic> J(6, n);
  Eigen::VectorXd tau(n);
  const int ft = model.link_index("ft_sensor");
  double checksum = 0.0;
  long allocations = 0;
  {
    AllocationCounter counter;
    for (const Eigen::VectorXd& q : qs) {
      const Pose tip = forward_kinematics(model, ws, q);
      const Pose sensor = forward_kinematics(model, ws, q, ft);
      jacobian(model, ws, q, J);
      jacobian(model, ws, q, J, ft);
      gravity_torques(model, ws, q, tau);
      checksum += tip.translation().x() + sensor.translation().z() + J(0, 0) + tau[1];
    }
    allocations = counter.count();
  }
  EXPECT_EQ(allocations, 0) << "the real-time kinematics allocated";
  EXPECT_TRUE(std::isfinite(checksum));
}
