#pragma once
// What a test needs to know about the sanitizer it runs under.

namespace foresight::test {

/// True in an AddressSanitizer build (scripts/sanitize.sh asan|asan-ci).
///
/// Cyclone DDS 0.10.2 refuses to write a sample whose enum or union
/// discriminator is outside its type ("Bad Parameter"), and afterwards leaks
/// ~200-256 bytes per refused write on one of its own threads (LeakSanitizer:
/// allocated under start_thread, every frame in libddsc; found by the
/// whole-suite ASan run, bisected to those writes). Only a suppression of all
/// of libddsc could hide it, which would hide our own leaks through Cyclone
/// too; so the tests that show Cyclone's refusal (which checks Cyclone, not
/// our code) leave those writes out under ASan.
#if defined(__SANITIZE_ADDRESS__)
inline constexpr bool kAddressSanitizer = true;
#elif defined(__has_feature)
#if __has_feature(address_sanitizer)
inline constexpr bool kAddressSanitizer = true;
#else
inline constexpr bool kAddressSanitizer = false;
#endif
#else
inline constexpr bool kAddressSanitizer = false;
#endif

}  // namespace foresight::test
