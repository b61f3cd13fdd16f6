#include "foresight/protocol/dds.hpp"

#include <algorithm>
#include <cstdio>

namespace foresight::protocol {

Participant::Participant(dds_domainid_t domain)
    : entity_(dds_create_participant(domain, nullptr, nullptr),
              "create participant in domain " + std::to_string(domain)),
      domain_(domain) {}

Participant::Participant(dds_domainid_t domain, const Qos& qos)
    : entity_(dds_create_participant(domain, qos.get(), nullptr),
              "create participant in domain " + std::to_string(domain)),
      domain_(domain) {}

GuardCondition::GuardCondition(const Participant& participant)
    : entity_(dds_create_guardcondition(participant.get()), "create guard condition") {}

void GuardCondition::trigger() { check(dds_set_guardcondition(entity_.get(), true), "trigger guard condition"); }
void GuardCondition::reset() { check(dds_set_guardcondition(entity_.get(), false), "reset guard condition"); }
bool GuardCondition::triggered() const {
  bool value = false;
  check(dds_read_guardcondition(entity_.get(), &value), "read guard condition");
  return value;
}

WaitSet::WaitSet(const Participant& participant)
    : entity_(dds_create_waitset(participant.get()), "create waitset") {}

void WaitSet::attach_entity(dds_entity_t entity, dds_attach_t token, const std::string& what) {
  check(dds_waitset_attach(entity_.get(), entity, token), what);
}

int WaitSet::wait(std::chrono::nanoseconds timeout, std::span<dds_attach_t> triggered) {
  const dds_return_t n = dds_waitset_wait(entity_.get(), triggered.empty() ? nullptr : triggered.data(),
                                          triggered.size(), detail::to_dds(timeout));
  return static_cast<int>(check(n, "wait on waitset"));
}

namespace detail {

dds_duration_t to_dds(std::chrono::nanoseconds d) noexcept {
  return std::max<dds_duration_t>(0, static_cast<dds_duration_t>(d.count()));
}

std::uint32_t matched_count(dds_entity_t entity, bool writer) {
  if (writer) {
    dds_publication_matched_status_t status;
    check(dds_get_publication_matched_status(entity, &status), "get publication matched status");
    return status.current_count;
  }
  dds_subscription_matched_status_t status;
  check(dds_get_subscription_matched_status(entity, &status), "get subscription matched status");
  return status.current_count;
}

bool wait_matched(dds_entity_t entity, bool writer, std::uint32_t count, std::chrono::nanoseconds timeout) {
  const auto deadline = std::chrono::steady_clock::now() + timeout;
  const dds_entity_t participant = check(dds_get_participant(entity), "get participant");
  Entity waitset(dds_create_waitset(participant), "create waitset for matching");
  check(dds_set_status_mask(entity, writer ? DDS_PUBLICATION_MATCHED_STATUS : DDS_SUBSCRIPTION_MATCHED_STATUS),
        "set status mask");
  check(dds_waitset_attach(waitset.get(), entity, 0), "attach for matching");
  for (;;) {
    // Reading the status resets its trigger, so a change after this point
    // wakes the wait below.
    if (matched_count(entity, writer) >= count) return true;
    const auto left = deadline - std::chrono::steady_clock::now();
    if (left <= std::chrono::nanoseconds::zero()) return false;
    check(dds_waitset_wait(waitset.get(), nullptr, 0, to_dds(left)), "wait for matching");
  }
}

}  // namespace detail
ParticipantGuid writer_participant(dds_entity_t reader, dds_instance_handle_t publication_handle) {
  ParticipantGuid g;
  if (publication_handle == 0) return g;
  dds_builtintopic_endpoint_t* ep = dds_get_matched_publication_data(reader, publication_handle);
  if (ep == nullptr) return g;
  static_assert(sizeof(ep->participant_key.v) == 16);
  std::copy(std::begin(ep->participant_key.v), std::end(ep->participant_key.v), g.bytes.begin());
  dds_builtintopic_free_endpoint(ep);
  return g;
}

}  // namespace foresight::protocol
