#pragma once
// A test client written with the OpenIGTLink library (Debian libopenigtlink 1.11): receives and
// unpacks (CRC checked) what a server sends, with a bounded wait, and sends GET_POLYDATA.
#include <string>

#include "igtlClientSocket.h"
#include "igtlImageMessage.h"
#include "igtlMessageHeader.h"
#include "igtlPolyDataMessage.h"
#include "igtlStatusMessage.h"
#include "sonoshape/testing/sanitizer_slowdown.hpp"

namespace sonoshape::testing {

// One received message: its header and, for the types the tests look into, the unpacked body.
struct Received {
  std::string type, name;
  igtl::PolyDataMessage::Pointer polydata;
  igtl::ImageMessage::Pointer image;
  igtl::StatusMessage::Pointer status;
};

inline unsigned triangles(const Received& r) {
  igtl::PolyDataCellArray* polygons = r.polydata->GetPolygons();
  return polygons ? polygons->GetNumberOfCells() : 0u;
}

class IgtlClient {
 public:
  /// `receive_timeout_s` without a message ends a watch (scaled in sanitizer builds, whose scans
  /// are slower): bounded, so that a missing message fails the test instead of hanging it.
  explicit IgtlClient(int port, double receive_timeout_s = 5.0)
      : socket_(igtl::ClientSocket::New()) {
    connected_ = socket_->ConnectToServer("127.0.0.1", port) == 0;
    socket_->SetReceiveTimeout(static_cast<int>(1000.0 * receive_timeout_s * kSanitizerSlowdown));
  }
  ~IgtlClient() { close(); }
  bool connected() const { return connected_; }
  void close() { socket_->CloseSocket(); }

  /// The next message, or type "" when none came within the timeout.
  Received next() {
    Received r;
    igtl::MessageHeader::Pointer header = igtl::MessageHeader::New();
    header->InitPack();
    if (socket_->Receive(header->GetPackPointer(), header->GetPackSize()) != header->GetPackSize())
      return r;
    header->Unpack();
    r.type = header->GetDeviceType();
    r.name = header->GetDeviceName();
    if (r.type == "POLYDATA") {
      r.polydata = igtl::PolyDataMessage::New();
      if (!receive_body(r.polydata, header)) r.type = "POLYDATA (bad)";
    } else if (r.type == "IMAGE") {
      r.image = igtl::ImageMessage::New();
      if (!receive_body(r.image, header)) r.type = "IMAGE (bad)";
    } else if (r.type == "STATUS") {
      r.status = igtl::StatusMessage::New();
      if (!receive_body(r.status, header)) r.type = "STATUS (bad)";
    } else {
      socket_->Skip(header->GetBodySizeToRead(), 0);
    }
    return r;
  }

  void get_polydata(const std::string& name) {
    igtl::GetPolyDataMessage::Pointer get = igtl::GetPolyDataMessage::New();
    get->SetDeviceName(name.c_str());
    get->Pack();
    socket_->Send(get->GetPackPointer(), get->GetPackSize());
  }

 private:
  template <typename M>
  bool receive_body(M& message, igtl::MessageHeader::Pointer& header) {
    message->SetMessageHeader(header);
    message->AllocatePack();
    if (socket_->Receive(message->GetPackBodyPointer(), message->GetPackBodySize()) !=
        message->GetPackBodySize())
      return false;
    return (message->Unpack(1) & igtl::MessageHeader::UNPACK_BODY) != 0;  // CRC checked
  }

  igtl::ClientSocket::Pointer socket_;
  bool connected_ = false;
};

}  // namespace sonoshape::testing
