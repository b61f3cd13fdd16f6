// The journal tests' allocation counter (foresight/test/allocation_counter.hpp
// replaces operator new: one file per binary).
#include "foresight/test/allocation_counter.hpp"
#include "journal_test_util.hpp"

namespace foresight::journal::test {

long allocations_in(const std::function<void()>& work) {
  foresight::test::AllocationCounter counter;
  work();
  return counter.count();
}

}  // namespace foresight::journal::test
