// foresight_fastdds_peer: an eProsima Fast DDS participant built from the
// protocol's IDL (fastddsgen; the bounds as literals, see CMakeLists.txt), for
// the interoperability test with Cyclone DDS on loopback. It
//   - reads JointState on foresight/telemetry/joint_state and writes every
//     sample back unchanged on foresight/telemetry/joint_state/echo;
//   - answers Ping with Pong (t2 on arrival, t3 before the write).
// UDPv4 on 127.0.0.1 only (no shared memory: Cyclone does not speak it).
// Exits on SIGTERM/SIGINT, when its parent dies, or after --lifetime-s.
//
// Usage: foresight_fastdds_peer --domain N [--lifetime-s S]

#include <signal.h>
#include <sys/prctl.h>

#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <ctime>
#include <memory>
#include <string>

#include <fastdds/dds/domain/DomainParticipant.hpp>
#include <fastdds/dds/domain/DomainParticipantFactory.hpp>
#include <fastdds/dds/publisher/DataWriter.hpp>
#include <fastdds/dds/publisher/Publisher.hpp>
#include <fastdds/dds/subscriber/DataReader.hpp>
#include <fastdds/dds/subscriber/DataReaderListener.hpp>
#include <fastdds/dds/subscriber/SampleInfo.hpp>
#include <fastdds/dds/subscriber/Subscriber.hpp>
#include <fastdds/dds/topic/Topic.hpp>
#include <fastdds/dds/topic/TypeSupport.hpp>
#include <fastdds/rtps/transport/UDPv4TransportDescriptor.h>
#include <fastrtps/utils/IPLocator.h>

#include "foresight_interopPubSubTypes.h"

using namespace eprosima::fastdds::dds;
namespace fm = foresight::msg;

namespace {

std::int64_t realtime_ns() {
  timespec ts{};
  clock_gettime(CLOCK_REALTIME, &ts);
  return static_cast<std::int64_t>(ts.tv_sec) * 1'000'000'000 + ts.tv_nsec;
}

class EchoJointState : public DataReaderListener {
 public:
  explicit EchoJointState(DataWriter* echo) : echo_(echo) {}
  void on_data_available(DataReader* reader) override {
    SampleInfo info;
    while (reader->take_next_sample(&sample_, &info) == ReturnCode_t::RETCODE_OK) {
      if (info.valid_data) echo_->write(&sample_);
    }
  }

 private:
  DataWriter* echo_;
  fm::JointState sample_;
};

class AnswerPing : public DataReaderListener {
 public:
  explicit AnswerPing(DataWriter* pong) : pong_(pong) {}
  void on_data_available(DataReader* reader) override {
    SampleInfo info;
    while (reader->take_next_sample(&ping_, &info) == ReturnCode_t::RETCODE_OK) {
      if (!info.valid_data) continue;
      fm::Pong pong;
      pong.remote_receive_ns(realtime_ns());
      pong.ping_id(ping_.ping_id());
      pong.ground_send_ns(ping_.ground_send_ns());
      pong.remote_send_ns(realtime_ns());
      pong_->write(&pong);
    }
  }

 private:
  DataWriter* pong_;
  fm::Ping ping_;
};

int usage(const char* why) {
  std::fprintf(stderr, "foresight_fastdds_peer: %s\nusage: foresight_fastdds_peer --domain N [--lifetime-s S]\n", why);
  return 2;
}

}  // namespace

int main(int argc, char** argv) {
  prctl(PR_SET_PDEATHSIG, SIGTERM);
  long domain = -1;
  double lifetime_s = 120.0;
  for (int i = 1; i + 1 < argc; i += 2) {
    const std::string key = argv[i];
    if (key == "--domain") domain = std::strtol(argv[i + 1], nullptr, 10);
    else if (key == "--lifetime-s") lifetime_s = std::strtod(argv[i + 1], nullptr);
    else return usage(("unknown option " + key).c_str());
  }
  if (domain < 0 || domain > 230) return usage("--domain wants an integer in 0..230");
  sigset_t stop;
  sigemptyset(&stop);
  sigaddset(&stop, SIGTERM);
  sigaddset(&stop, SIGINT);
  pthread_sigmask(SIG_BLOCK, &stop, nullptr);

  DomainParticipantQos pqos;
  pqos.name("foresight_fastdds_peer");
  pqos.transport().use_builtin_transports = false;
  auto udp = std::make_shared<eprosima::fastdds::rtps::UDPv4TransportDescriptor>();
  udp->interfaceWhiteList.push_back("127.0.0.1");
  pqos.transport().user_transports.push_back(udp);
  // Unicast discovery of the loopback peers (Cyclone's side does the same).
  eprosima::fastrtps::rtps::Locator_t peer;
  eprosima::fastrtps::rtps::IPLocator::setIPv4(peer, 127, 0, 0, 1);
  pqos.wire_protocol().builtin.initialPeersList.push_back(peer);
  auto* factory = DomainParticipantFactory::get_instance();
  DomainParticipant* participant = factory->create_participant(static_cast<DomainId_t>(domain), pqos);
  if (participant == nullptr) {
    std::fprintf(stderr, "foresight_fastdds_peer: cannot create the participant\n");
    return 1;
  }
  TypeSupport joint_type(new fm::JointStatePubSubType());
  TypeSupport ping_type(new fm::PingPubSubType());
  TypeSupport pong_type(new fm::PongPubSubType());
  joint_type.register_type(participant);
  ping_type.register_type(participant);
  pong_type.register_type(participant);
  Topic* joint_topic = participant->create_topic("foresight/telemetry/joint_state", joint_type.get_type_name(),
                                                 TOPIC_QOS_DEFAULT);
  Topic* echo_topic = participant->create_topic("foresight/telemetry/joint_state/echo", joint_type.get_type_name(),
                                                TOPIC_QOS_DEFAULT);
  Topic* ping_topic = participant->create_topic("foresight/ping", ping_type.get_type_name(), TOPIC_QOS_DEFAULT);
  Topic* pong_topic = participant->create_topic("foresight/pong", pong_type.get_type_name(), TOPIC_QOS_DEFAULT);
  Publisher* publisher = participant->create_publisher(PUBLISHER_QOS_DEFAULT);
  Subscriber* subscriber = participant->create_subscriber(SUBSCRIBER_QOS_DEFAULT);
  if (!joint_topic || !echo_topic || !ping_topic || !pong_topic || !publisher || !subscriber) {
    std::fprintf(stderr, "foresight_fastdds_peer: cannot create the topics\n");
    return 1;
  }
  // The protocol's QoS for these topics: best effort, keep-last, volatile.
  DataWriterQos wqos = DATAWRITER_QOS_DEFAULT;
  wqos.reliability().kind = BEST_EFFORT_RELIABILITY_QOS;
  wqos.history().kind = KEEP_LAST_HISTORY_QOS;
  wqos.history().depth = 16;
  DataReaderQos rqos = DATAREADER_QOS_DEFAULT;
  rqos.reliability().kind = BEST_EFFORT_RELIABILITY_QOS;
  rqos.history().kind = KEEP_LAST_HISTORY_QOS;
  rqos.history().depth = 16;
  DataWriter* echo = publisher->create_datawriter(echo_topic, wqos);
  DataWriter* pong = publisher->create_datawriter(pong_topic, wqos);
  EchoJointState echo_listener(echo);
  AnswerPing ping_listener(pong);
  DataReader* joints = subscriber->create_datareader(joint_topic, rqos, &echo_listener);
  DataReader* pings = subscriber->create_datareader(ping_topic, rqos, &ping_listener);
  if (!echo || !pong || !joints || !pings) {
    std::fprintf(stderr, "foresight_fastdds_peer: cannot create the readers and writers\n");
    return 1;
  }
  const auto start = std::chrono::steady_clock::now();
  const timespec tick{0, 200'000'000};
  for (;;) {
    const int sig = sigtimedwait(&stop, nullptr, &tick);
    if (sig == SIGTERM || sig == SIGINT) break;
    if (std::chrono::steady_clock::now() - start > std::chrono::duration<double>(lifetime_s)) break;
  }
  participant->delete_contained_entities();
  factory->delete_participant(participant);
  return 0;
}
