#pragma once
// A thin RAII layer over the Cyclone DDS C API (Debian ships no C++ binding).
//
// - Every entity is owned by exactly one move-only C++ object and deleted in
//   its destructor (deleting a parent also deletes its children in Cyclone, so
//   destroying a Participant first is harmless: the children's deletes then
//   fail quietly).
// - Every return code is checked; failures throw ProtocolError carrying
//   Cyclone's error text (dds_strretcode).
// - No listeners: Cyclone calls listeners on its own threads, where creating
//   entities deadlocks and exceptions must not unwind. Readers are served
//   from a WaitSet on the application's thread instead.
// - Readers take into caller-owned Sample<T>s: Cyclone deserializes into the
//   existing sample and reuses its sequence buffers when they are large
//   enough (types with unions are freed and rebuilt by Cyclone), so a
//   steady stream of same-sized samples does not allocate in take().
//
// Thread safety: distinct entities may be used from distinct threads; one
// Writer or Reader object from one thread at a time. GuardCondition::trigger
// may be called from any thread (e.g. to wake a link loop for shutdown).
// Nothing here is for a real-time control cycle: writes serialize and may
// block (reliable topics), set-up allocates. try_write() is noexcept for link
// threads that must not throw.

#include <dds/dds.h>
#include <dds/ddsi/ddsi_serdata.h>

#include <chrono>
#include <cstdint>
#include <optional>
#include <span>
#include <string>
#include <utility>

#include "foresight/protocol/cdr_check.hpp"
#include "foresight/protocol/command.hpp"
#include "foresight/protocol/error.hpp"
#include "foresight/protocol/messages.hpp"
#include "foresight/protocol/qos.hpp"

namespace foresight::protocol {

/// Owns one dds_entity_t (0 = none); dds_delete on destruction.
class Entity {
 public:
  Entity() noexcept = default;
  /// Takes ownership of `handle`; throws ProtocolError when it is an error code.
  Entity(dds_entity_t handle, const std::string& what) : handle_(check(handle, what)) {}
  ~Entity() { reset(); }
  Entity(Entity&& other) noexcept : handle_(std::exchange(other.handle_, 0)) {}
  Entity& operator=(Entity&& other) noexcept {
    if (this != &other) {
      reset();
      handle_ = std::exchange(other.handle_, 0);
    }
    return *this;
  }
  Entity(const Entity&) = delete;
  Entity& operator=(const Entity&) = delete;

  dds_entity_t get() const noexcept { return handle_; }
  explicit operator bool() const noexcept { return handle_ > 0; }
  /// Deletes the entity now (errors ignored: the parent may already be gone).
  void reset() noexcept {
    if (handle_ > 0) (void)dds_delete(handle_);
    handle_ = 0;
  }

 private:
  dds_entity_t handle_ = 0;
};

/// A domain participant. Reads its configuration from CYCLONEDDS_URI when the
/// domain is first created in this process (see loopback.hpp for tests).
class Participant {
 public:
  explicit Participant(dds_domainid_t domain = DDS_DOMAIN_DEFAULT);
  /// With a participant QoS, e.g. security_qos() (security.hpp).
  Participant(dds_domainid_t domain, const Qos& qos);
  dds_entity_t get() const noexcept { return entity_.get(); }
  dds_domainid_t domain() const noexcept { return domain_; }

 private:
  Entity entity_;
  dds_domainid_t domain_;
};

/// A typed sample that owns whatever Cyclone (or assign()) allocated inside
/// it (sequences); freed with dds_sample_free(DDS_FREE_CONTENTS). Starts
/// zeroed. Move-only (moving transfers the buffers and zeroes the source).
template <Message T>
class Sample {
 public:
  Sample() noexcept : value_{} {}
  ~Sample() { free_contents(); }
  Sample(Sample&& other) noexcept : value_(other.value_) { other.value_ = T{}; }
  Sample& operator=(Sample&& other) noexcept {
    if (this != &other) {
      free_contents();
      value_ = other.value_;
      other.value_ = T{};
    }
    return *this;
  }
  Sample(const Sample&) = delete;
  Sample& operator=(const Sample&) = delete;

  T& operator*() noexcept { return value_; }
  const T& operator*() const noexcept { return value_; }
  T* operator->() noexcept { return &value_; }
  const T* operator->() const noexcept { return &value_; }
  T* get() noexcept { return &value_; }
  const T* get() const noexcept { return &value_; }

  /// Frees the contents and zeroes the sample.
  void clear() noexcept {
    free_contents();
    value_ = T{};
  }

 private:
  void free_contents() noexcept { dds_sample_free(&value_, MessageTraits<T>::descriptor(), DDS_FREE_CONTENTS); }
  T value_;
};

/// A topic of type T in a participant.
template <Message T>
class Topic {
 public:
  explicit Topic(const Participant& participant, const std::string& name = MessageTraits<T>::topic)
      : name_(name),
        entity_(dds_create_topic(participant.get(), MessageTraits<T>::descriptor(), name.c_str(), nullptr, nullptr),
                "create topic " + name + " (" + MessageTraits<T>::type_name + ")") {}
  dds_entity_t get() const noexcept { return entity_.get(); }
  const std::string& name() const noexcept { return name_; }

 private:
  std::string name_;
  Entity entity_;
};

namespace detail {
/// Waits until the matched count (publication- or subscription-matched) of
/// `entity` reaches `count` or `timeout` passes. Returns whether it did.
bool wait_matched(dds_entity_t entity, bool writer, std::uint32_t count, std::chrono::nanoseconds timeout);
std::uint32_t matched_count(dds_entity_t entity, bool writer);
dds_duration_t to_dds(std::chrono::nanoseconds d) noexcept;
}  // namespace detail

/// The participant whose writer wrote a sample `reader` took (the sample
/// info's publication_handle, through the reader's matched publication);
/// unknown when that writer is no longer matched. Allocates (not for the
/// control cycle).
ParticipantGuid writer_participant(dds_entity_t reader, dds_instance_handle_t publication_handle);

template <Message T>
class Writer {
 public:
  /// Creates the topic (default name of T) and a writer with `qos` (default profile of T).
  explicit Writer(const Participant& participant, const std::string& topic = MessageTraits<T>::topic,
                  const Qos& qos = MessageTraits<T>::qos())
      : topic_(participant, topic),
        entity_(dds_create_writer(participant.get(), topic_.get(), qos.get(), nullptr), "create writer on " + topic) {}

  /// Publishes `sample`. Throws ProtocolError (e.g. "Timeout" when a reliable
  /// reader stopped acknowledging, "Bad parameter" when a bounded string or
  /// sequence exceeds its bound).
  void write(const T& sample) { check(dds_write(entity_.get(), &sample), "write on " + topic_.name()); }
  void write(const Sample<T>& sample) { write(*sample); }
  /// As write(), returning Cyclone's return code instead of throwing.
  dds_return_t try_write(const T& sample) noexcept { return dds_write(entity_.get(), &sample); }

  /// Keyed topics: tell readers the instance (by the key fields of `key`) is gone.
  void dispose(const T& key) { check(dds_dispose(entity_.get(), &key), "dispose on " + topic_.name()); }

  std::uint32_t matched_readers() const { return detail::matched_count(entity_.get(), true); }
  /// Blocks until at least `count` readers matched (discovery) or `timeout`.
  bool wait_for_readers(std::uint32_t count, std::chrono::nanoseconds timeout) const {
    return detail::wait_matched(entity_.get(), true, count, timeout);
  }
  /// Reliable writers: blocks until every matched reader acknowledged all
  /// samples written so far. False on timeout.
  bool wait_for_acks(std::chrono::nanoseconds timeout) const {
    const dds_return_t rc = dds_wait_for_acks(entity_.get(), detail::to_dds(timeout));
    if (rc == DDS_RETCODE_TIMEOUT) return false;
    check(rc, "wait for acks on " + topic_.name());
    return true;
  }

  dds_entity_t get() const noexcept { return entity_.get(); }
  const std::string& topic() const noexcept { return topic_.name(); }

 private:
  Topic<T> topic_;
  Entity entity_;
};

template <Message T>
class Reader {
 public:
  explicit Reader(const Participant& participant, const std::string& topic = MessageTraits<T>::topic,
                  const Qos& qos = MessageTraits<T>::qos())
      : topic_(participant, topic),
        entity_(dds_create_reader(participant.get(), topic_.get(), qos.get(), nullptr), "create reader on " + topic),
        condition_(dds_create_readcondition(entity_.get(), DDS_ANY_STATE), "create read condition on " + topic),
        waitset_(dds_create_waitset(participant.get()), "create waitset for " + topic) {
    check(dds_waitset_attach(waitset_.get(), condition_.get(), 0), "attach reader of " + topic);
  }

  /// Takes the next sample with valid data into `out` (reusing its buffers)
  /// and returns true; returns false when none is waiting. Dispose and
  /// unregister notifications (no data) are consumed and skipped. `info`
  /// receives the sample info (source timestamp, instance state, ...).
  bool take(Sample<T>& out, dds_sample_info_t* info = nullptr) {
    return take_checked(out, info);
  }

  /// Samples dropped before Cyclone built them, since the reader was created:
  /// a member, sequence or string longer than the bytes the sample carries
  /// (cdr_check.hpp), or a DHEADER shorter than the type's min_dheader
  /// (messages.hpp).
  std::uint64_t malformed_dropped() const noexcept { return malformed_dropped_; }

  /// Waits up to `timeout` for a sample and takes it. False on timeout.
  bool wait_take(Sample<T>& out, std::chrono::nanoseconds timeout, dds_sample_info_t* info = nullptr) {
    const auto deadline = std::chrono::steady_clock::now() + timeout;
    for (;;) {
      if (take(out, info)) return true;
      const auto left = deadline - std::chrono::steady_clock::now();
      if (left <= std::chrono::nanoseconds::zero()) return false;
      check(dds_waitset_wait(waitset_.get(), nullptr, 0, detail::to_dds(left)), "wait on " + topic_.name());
    }
  }

  std::uint32_t matched_writers() const { return detail::matched_count(entity_.get(), false); }
  /// Blocks until at least `count` writers matched (discovery) or `timeout`.
  bool wait_for_writers(std::uint32_t count, std::chrono::nanoseconds timeout) const {
    return detail::wait_matched(entity_.get(), false, count, timeout);
  }

  dds_entity_t get() const noexcept { return entity_.get(); }
  /// Triggers while samples are waiting; attach it to a WaitSet.
  dds_entity_t read_condition() const noexcept { return condition_.get(); }
  const std::string& topic() const noexcept { return topic_.name(); }

 private:
  static constexpr std::uint32_t kMinDheader = [] {
    if constexpr (requires { MessageTraits<T>::min_dheader; }) return MessageTraits<T>::min_dheader;
    else return std::uint32_t{0};
  }();

  /// take() through the serialized sample: before Cyclone builds the C
  /// struct (ddsi_serdata_to_sample), the sample's CDR is walked member by
  /// member (cdr_check.hpp: every length against the bytes left; Cyclone
  /// 0.10.2's own check lets 8-byte values and sequences of them run past the
  /// data, and its read then over-reads the heap), and a Command's DHEADER is
  /// checked against min_dheader. A sample that fails is dropped and counted.
  bool take_checked(Sample<T>& out, dds_sample_info_t* info) {
    for (;;) {
      ddsi_serdata* data = nullptr;
      dds_sample_info_t local_info;
      const dds_return_t n = dds_takecdr(entity_.get(), &data, 1, &local_info, DDS_ANY_STATE);
      check(n, "take on " + topic_.name());
      if (n == 0) return false;
      bool ok = false;
      if (local_info.valid_data) {
        ok = serialized_fits(data) && ddsi_serdata_to_sample(data, out.get(), nullptr, nullptr);
        if (!ok) ++malformed_dropped_;
      }
      ddsi_serdata_unref(data);
      if (ok) {
        if (info != nullptr) *info = local_info;
        return true;
      }
    }
  }

  /// The encapsulation header, min_dheader and the layout walk over the
  /// serialized bytes in place (no copy).
  static bool serialized_fits(ddsi_serdata* data) noexcept {
    const std::uint32_t size = ddsi_serdata_size(data);
    if (size < 4) return false;
    ddsrt_iovec_t ref{};
    ddsi_serdata* held = ddsi_serdata_to_ser_ref(data, 0, size, &ref);
    const std::span<const unsigned char> bytes(static_cast<const unsigned char*>(ref.iov_base), ref.iov_len);
    bool ok = false;
    if (const std::optional<CdrPayload> payload = cdr_payload(bytes)) {
      ok = cdr_fits<T>(*payload);
      if (ok && kMinDheader > 0) {
        // An appendable type's DHEADER (XCDR2 only) in the payload's byte order.
        const unsigned char* h = payload->bytes.data();
        const std::uint32_t dheader =
            payload->bytes.size() < 4 ? 0
            : payload->little_endian
                ? h[0] | (h[1] << 8) | (h[2] << 16) | (static_cast<std::uint32_t>(h[3]) << 24)
                : h[3] | (h[2] << 8) | (h[1] << 16) | (static_cast<std::uint32_t>(h[0]) << 24);
        ok = dheader >= kMinDheader;
      }
    }
    ddsi_serdata_to_ser_unref(held, &ref);
    return ok;
  }

  Topic<T> topic_;
  Entity entity_;
  Entity condition_;  // child of entity_: declared after it, so deleted first
  Entity waitset_;
  std::uint64_t malformed_dropped_ = 0;
};

/// A condition the application triggers itself, e.g. to wake a waiting loop
/// for shutdown. trigger() may be called from any thread.
class GuardCondition {
 public:
  explicit GuardCondition(const Participant& participant);
  void trigger();
  void reset();
  bool triggered() const;
  dds_entity_t get() const noexcept { return entity_.get(); }

 private:
  Entity entity_;
};

/// Waits on readers (data available) and guard conditions.
class WaitSet {
 public:
  explicit WaitSet(const Participant& participant);

  template <Message T>
  void attach(const Reader<T>& reader, dds_attach_t token = 0) {
    attach_entity(reader.read_condition(), token, "attach reader of " + reader.topic());
  }
  void attach(const GuardCondition& guard, dds_attach_t token = 0) {
    attach_entity(guard.get(), token, "attach guard condition");
  }
  template <Message T>
  void detach(const Reader<T>& reader) {
    check(dds_waitset_detach(entity_.get(), reader.read_condition()), "detach reader of " + reader.topic());
  }
  void detach(const GuardCondition& guard) { check(dds_waitset_detach(entity_.get(), guard.get()), "detach guard"); }

  /// Blocks until an attached condition triggers or `timeout` passes; returns
  /// how many triggered (0 = timeout). Their tokens go to `triggered` (as many
  /// as fit).
  int wait(std::chrono::nanoseconds timeout, std::span<dds_attach_t> triggered = {});

  dds_entity_t get() const noexcept { return entity_.get(); }

 private:
  void attach_entity(dds_entity_t entity, dds_attach_t token, const std::string& what);
  Entity entity_;
};

}  // namespace foresight::protocol
