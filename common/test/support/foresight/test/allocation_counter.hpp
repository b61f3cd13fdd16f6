#pragma once
// Counting every heap allocation, for the tests that prove real-time code
// allocation-free (FK/Jacobian/gravity, the CAN cycle, the contact and screw
// models). Include this header in exactly ONE source file of a test binary:
// it defines the replacements of the C allocator (malloc, calloc, realloc,
// the aligned forms: Eigen and C libraries allocate through malloc, not
// operator new) and of the global operator new/delete, forwarding to glibc's
// __libc_* functions (glibc-specific, like the project).
//
// Only the thread that armed an AllocationCounter is counted: a simulator
// thread beside the cycle allocates freely (it is not real-time code).
//
// Under ASan or TSan (cmake/Sanitizers.cmake) nothing is replaced: the
// sanitizer owns malloc (a replacement forwarding to __libc_malloc crashes
// inside ASan's start-up), and the count comes from the sanitizer's own
// allocation hook (__sanitizer_install_malloc_and_free_hooks), which sees
// malloc, calloc, realloc, the aligned forms and operator new alike.

#include "foresight/test/sanitizer.hpp"

#if FORESIGHT_TEST_ASAN || FORESIGHT_TEST_TSAN
#define FORESIGHT_ALLOC_COUNT_BY_HOOK 1
#endif

#include <malloc.h>     // memalign, as glibc declares it
#include <mm_malloc.h>  // posix_memalign as GCC declares it: before the definitions below

#include <atomic>
#include <cerrno>
#include <cstddef>
#include <cstdlib>
#include <new>
#include <stdexcept>

#ifndef FORESIGHT_ALLOC_COUNT_BY_HOOK
extern "C" {
void* __libc_malloc(std::size_t);
void* __libc_calloc(std::size_t, std::size_t);
void* __libc_realloc(void*, std::size_t);
void* __libc_memalign(std::size_t, std::size_t);
void __libc_free(void*);
}
#endif

namespace foresight::test::alloc_detail {
inline thread_local bool counting = false;  // zero-initialized static TLS: no allocation to read it
inline std::atomic<long> allocations{0};
inline void count() {
  if (counting) allocations.fetch_add(1, std::memory_order_relaxed);
}
inline void* checked(void* p) {
  if (p == nullptr) throw std::bad_alloc();
  return p;
}
}  // namespace foresight::test::alloc_detail

#ifdef FORESIGHT_ALLOC_COUNT_BY_HOOK
// Declared by <sanitizer/allocator_interface.h> (Clang); GCC ships the symbol
// in libasan/libtsan without that header.
extern "C" int __sanitizer_install_malloc_and_free_hooks(void (*malloc_hook)(const volatile void*, std::size_t),
                                                         void (*free_hook)(const volatile void*));
namespace foresight::test::alloc_detail {
inline void malloc_hook(const volatile void*, std::size_t) { count(); }
inline void free_hook(const volatile void*) {}
/// Installs the hook once (the sanitizer takes at most 5 hooks); true when installed.
inline bool install_hook() {
  static const bool installed = __sanitizer_install_malloc_and_free_hooks(&malloc_hook, &free_hook) != 0;
  return installed;
}
}  // namespace foresight::test::alloc_detail
#else

// ---- the C allocator (noexcept, as glibc declares them) ----
extern "C" {
void* malloc(std::size_t n) noexcept {
  foresight::test::alloc_detail::count();
  return __libc_malloc(n);
}
void* calloc(std::size_t n, std::size_t size) noexcept {
  foresight::test::alloc_detail::count();
  return __libc_calloc(n, size);
}
void* realloc(void* p, std::size_t n) noexcept {
  foresight::test::alloc_detail::count();
  return __libc_realloc(p, n);
}
void* memalign(std::size_t a, std::size_t n) noexcept {
  foresight::test::alloc_detail::count();
  return __libc_memalign(a, n);
}
void* aligned_alloc(std::size_t a, std::size_t n) noexcept {
  foresight::test::alloc_detail::count();
  return __libc_memalign(a, n);
}
int posix_memalign(void** out, std::size_t a, std::size_t n) noexcept {
  foresight::test::alloc_detail::count();
  void* p = __libc_memalign(a, n);
  if (p == nullptr) return ENOMEM;
  *out = p;
  return 0;
}
void free(void* p) noexcept { __libc_free(p); }
}

// ---- C++ operator new/delete ----
void* operator new(std::size_t n) {
  foresight::test::alloc_detail::count();
  return foresight::test::alloc_detail::checked(__libc_malloc(n == 0 ? 1 : n));
}
void* operator new[](std::size_t n) {
  foresight::test::alloc_detail::count();
  return foresight::test::alloc_detail::checked(__libc_malloc(n == 0 ? 1 : n));
}
void* operator new(std::size_t n, const std::nothrow_t&) noexcept {
  foresight::test::alloc_detail::count();
  return __libc_malloc(n == 0 ? 1 : n);
}
void* operator new[](std::size_t n, const std::nothrow_t&) noexcept {
  foresight::test::alloc_detail::count();
  return __libc_malloc(n == 0 ? 1 : n);
}
void* operator new(std::size_t n, std::align_val_t a) {
  foresight::test::alloc_detail::count();
  return foresight::test::alloc_detail::checked(__libc_memalign(static_cast<std::size_t>(a), n == 0 ? 1 : n));
}
void* operator new[](std::size_t n, std::align_val_t a) {
  foresight::test::alloc_detail::count();
  return foresight::test::alloc_detail::checked(__libc_memalign(static_cast<std::size_t>(a), n == 0 ? 1 : n));
}
void operator delete(void* p) noexcept { __libc_free(p); }
void operator delete[](void* p) noexcept { __libc_free(p); }
void operator delete(void* p, std::size_t) noexcept { __libc_free(p); }
void operator delete[](void* p, std::size_t) noexcept { __libc_free(p); }
void operator delete(void* p, std::align_val_t) noexcept { __libc_free(p); }
void operator delete[](void* p, std::align_val_t) noexcept { __libc_free(p); }
void operator delete(void* p, std::size_t, std::align_val_t) noexcept { __libc_free(p); }
void operator delete[](void* p, std::size_t, std::align_val_t) noexcept { __libc_free(p); }
#endif  // FORESIGHT_ALLOC_COUNT_BY_HOOK

namespace foresight::test {

/// Counts this thread's allocations while it is alive (not nestable).
class AllocationCounter {
 public:
  AllocationCounter() {
#ifdef FORESIGHT_ALLOC_COUNT_BY_HOOK
    if (!alloc_detail::install_hook()) throw std::runtime_error("cannot install the sanitizer malloc hook");
#endif
    alloc_detail::allocations = 0;
    alloc_detail::counting = true;
  }
  ~AllocationCounter() { alloc_detail::counting = false; }
  AllocationCounter(const AllocationCounter&) = delete;
  AllocationCounter& operator=(const AllocationCounter&) = delete;
  /// Allocations so far.
  long count() const { return alloc_detail::allocations.load(); }
  /// Stops counting (e.g. between cycles) and resumes; the count is kept.
  void pause() { alloc_detail::counting = false; }
  void resume() { alloc_detail::counting = true; }
};

}  // namespace foresight::test
