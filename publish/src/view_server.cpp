// ViewServer: the page over HTTP and the stream over WebSocket, with Boost.Beast.
//
// Why Boost.Beast: header-only (nothing to link but Asio's threads), packaged in Debian's
// libboost-dev that CGAL already needs, well kept (part of Boost, releases three times a year),
// and it speaks HTTP and WebSocket over one Asio socket, so the page and its stream share one
// port and one thread. All Beast and Asio types stay in this file.
#include "sonoshape/publish/view_server.hpp"

#include <algorithm>
#include <atomic>
#include <boost/asio/ip/tcp.hpp>
#include <boost/asio/post.hpp>
#include <boost/asio/steady_timer.hpp>
#include <boost/beast/core.hpp>
#include <boost/beast/http.hpp>
#include <boost/beast/websocket.hpp>
#include <cctype>
#include <deque>
#include <fstream>
#include <future>
#include <list>
#include <mutex>
#include <nlohmann/json.hpp>
#include <optional>
#include <sstream>
#include <thread>
#include <unordered_map>

#include "sonoshape/core/input_file.hpp"
#include "sonoshape/core/log.hpp"

namespace sonoshape::publish {
namespace {

namespace asio = boost::asio;
namespace beast = boost::beast;
namespace http = beast::http;
namespace websocket = beast::websocket;
using tcp = asio::ip::tcp;

// The limits below keep the view from taking memory, file descriptors or the page's reach from
// the scan, whatever a local program sends (issue 40, C1 and C2; docs/security.md).
//
// Connections of every kind at once (files and WebSockets). At the limit a new connection closes
// the oldest one that holds no WebSocket: a flood of half-open requests or of clients that do not
// read cannot keep the page out, since the page's own request then comes newest.
constexpr std::size_t kMaxConnections = 32;
// WebSockets (pages) at once; fewer than kMaxConnections, so that files are always served.
constexpr std::size_t kMaxPages = 16;
// The largest WebSocket message a page may send: the page sends none (close frames hold at most
// 125 bytes); a larger one closes that page's connection with code 1009 (too big).
constexpr std::size_t kMaxIncomingMessageBytes = 1024;
// Time to send one whole request, from the connection (or the previous answer) on.
constexpr std::chrono::seconds kRequestTimeout{10};
// Time to take one whole answer: three.js (2.4 MB) needs under 1 s on any link a page works over.
constexpr std::chrono::seconds kResponseTimeout{30};
// The largest request the server reads: the page only ever asks for files.
constexpr std::uint64_t kMaxRequestBytes = 16 * 1024;
constexpr std::uint32_t kMaxHeaderBytes = 8 * 1024;

void append_u32(std::string& out, std::uint32_t value) {
  for (int byte = 0; byte < 4; ++byte)
    out.push_back(static_cast<char>((value >> (8 * byte)) & 0xff));
}

// The slices a page keeps (and a late page is sent): every slice of a scan, up to this many, the
// oldest dropped beyond. A slice message is a few kilobytes.
constexpr std::size_t kMaxSlicesKept = 4096;

// One message on its way to the pages: packed once, shared by every connection.
struct Item {
  std::string topic;
  std::string scan;  // empty for `viewer` messages, which belong to no scan
  std::shared_ptr<const std::string> packed;
  // What a newer message replaces: its topic, except that every slice is its own ("slice#<seq>"),
  // since the page draws the slice planes so far and colours the surfaces by them.
  std::string key;
};

// Messages waiting for the pages, one per key: a newer message of a topic replaces the older one
// in its place; slices accumulate up to kMaxSlicesKept (the oldest dropped beyond); at most
// kMaxStreamLabels mesh labels a scan (a publisher with more is hostile or broken: the further
// labels are dropped and counted); a message of a new scan drops every item of other scans.
// Lookups by key are constant-time: a publisher's many labels cost the view nothing per message.
class Conflated {
 public:
  // Adds `item`; returns how many items it dropped or replaced. A mesh of a label beyond the
  // limit is not added: counted in `refused_labels`.
  std::uint64_t add(Item item, std::uint64_t* refused_labels = nullptr) {
    std::uint64_t dropped = 0;
    if (!item.scan.empty() && item.scan != scan_) {
      if (!scan_.empty()) dropped += drop_other_scans(item.scan);
      scan_ = item.scan;
    }
    if (const auto same = by_key_.find(item.key); same != by_key_.end()) {
      *same->second = std::move(item);
      return dropped + 1;
    }
    const bool slice = item.topic == kSliceTopic;
    const bool mesh = item.topic.starts_with(kMeshTopicPrefix);
    if (mesh && mesh_labels_ >= static_cast<std::size_t>(kMaxStreamLabels)) {
      if (refused_labels) ++*refused_labels;
      return dropped;
    }
    mesh_labels_ += mesh;
    const std::string key = item.key;
    items_.push_back(std::move(item));
    by_key_.emplace(key, std::prev(items_.end()));
    if (slice) slices_.push_back(std::prev(items_.end()));
    if (slices_.size() > kMaxSlicesKept) {
      erase(slices_.front());
      ++dropped;
    }
    return dropped;
  }

  bool empty() const { return items_.empty(); }
  std::size_t size() const { return items_.size(); }
  Item pop_front() {
    forget(items_.begin());  // while the item still has its key and topic
    Item item = std::move(items_.front());
    items_.pop_front();
    return item;
  }
  const std::list<Item>& items() const { return items_; }

 private:
  using Iterator = std::list<Item>::iterator;

  // Drops the bookkeeping of `it`, the oldest slice if it is a slice (the only ones erased).
  void forget(Iterator it) {
    by_key_.erase(it->key);
    if (it->topic == kSliceTopic && !slices_.empty() && slices_.front() == it) slices_.pop_front();
    mesh_labels_ -= it->topic.starts_with(kMeshTopicPrefix);
  }

  void erase(Iterator it) {
    forget(it);
    items_.erase(it);
  }

  std::uint64_t drop_other_scans(const std::string& scan) {
    std::uint64_t dropped = 0;
    for (auto it = items_.begin(); it != items_.end();) {
      const auto next = std::next(it);
      if (!it->scan.empty() && it->scan != scan) {
        if (it->topic == kSliceTopic) std::erase(slices_, it);
        by_key_.erase(it->key);
        mesh_labels_ -= it->topic.starts_with(kMeshTopicPrefix);
        items_.erase(it);
        ++dropped;
      }
      it = next;
    }
    return dropped;
  }

  std::list<Item> items_;  // in the order they are to be sent
  std::unordered_map<std::string, Iterator> by_key_;
  std::deque<Iterator> slices_;  // oldest first
  std::size_t mesh_labels_ = 0;
  std::string scan_;
};

// The scan uuid of a message (empty when it has none) and its conflation key.
std::pair<std::string, std::string> scan_and_key(const Frames& frames) {
  std::string key = frames[0];
  if (frames.size() < 2) return {{}, key};
  const nlohmann::json header = nlohmann::json::parse(frames[1], nullptr, false);
  if (!header.is_object()) return {{}, key};
  if (frames[0] == kSliceTopic && header.contains("seq")) key += "#" + header["seq"].dump();
  if (!header.contains("scan") || !header["scan"].is_string()) return {{}, key};
  return {header["scan"].get<std::string>(), key};
}

std::string_view content_type(const std::filesystem::path& path) {
  const std::string ext = path.extension().string();
  if (ext == ".html") return "text/html; charset=utf-8";
  if (ext == ".js") return "text/javascript; charset=utf-8";
  if (ext == ".css") return "text/css; charset=utf-8";
  if (ext == ".png") return "image/png";
  if (ext == ".json") return "application/json";
  return "application/octet-stream";
}

// The file a request target names, or none for a target outside what the page needs: the
// page's own files and three.js's build and addons, with no way up (`..`) or sideways.
std::optional<std::filesystem::path> resolve_target(const std::filesystem::path& root,
                                                    std::string_view target) {
  target = target.substr(0, target.find('?'));
  if (target == "/") return root / "index.html";
  if (target.empty() || target[0] != '/') return std::nullopt;
  const bool plain = std::all_of(target.begin(), target.end(), [](char c) {
    return std::isalnum(static_cast<unsigned char>(c)) || c == '.' || c == '_' || c == '-' ||
           c == '/';
  });
  if (!plain || target.find("..") != std::string_view::npos ||
      target.find("//") != std::string_view::npos)
    return std::nullopt;
  const std::string_view rest = target.substr(1);
  if (rest.starts_with("three/")) {
    const std::string_view inner = rest.substr(6);
    if (!inner.starts_with("build/") && !inner.starts_with("examples/jsm/")) return std::nullopt;
    return root / "node_modules" / "three" / std::string(inner);
  }
  if (rest == "index.html" || (rest.starts_with("src/") && rest.ends_with(".js")) ||
      rest == "style.css")
    return root / std::string(rest);
  return std::nullopt;
}

// The names under which the server is reached (DNS rebinding): a page of another site whose
// name is rebound to this machine's address reaches the server with that name in Host (and in
// Origin, for its WebSocket). Only this machine's own names are answered: the loopback names,
// the bound address and, when bound to every interface (0.0.0.0, ::), any IP address, which no
// rebinding can produce; each with the server's port (or none for port 80).
struct ServedNames {
  std::vector<std::string> names;  // lower-case hosts, IPv6 in brackets
  bool any_address = false;
  unsigned short port = 0;

  bool allows(std::string_view authority) const {
    std::string text = lower(authority);
    std::string host = text;
    std::string port_text;
    const std::size_t colon = text.rfind(':');
    if (colon != std::string::npos && text.find(']', colon) == std::string::npos) {
      host = text.substr(0, colon);
      port_text = text.substr(colon + 1);
    }
    if (port_text.empty() ? port != 80 : port_text != std::to_string(port)) return false;
    if (std::find(names.begin(), names.end(), host) != names.end()) return true;
    if (!any_address) return false;
    std::string bare = host;
    if (bare.size() > 2 && bare.front() == '[' && bare.back() == ']')
      bare = bare.substr(1, bare.size() - 2);
    else if (bare.find(':') != std::string::npos)
      return false;  // an IPv6 address must be in brackets
    beast::error_code ec;
    asio::ip::make_address(bare, ec);
    return !ec;
  }

  // An Origin header ("http://HOST:PORT"): the page must be one this server served.
  bool allows_origin(std::string_view origin) const {
    constexpr std::string_view kScheme = "http://";
    if (origin.substr(0, kScheme.size()) != kScheme) return false;
    return allows(origin.substr(kScheme.size()));
  }

  static std::string lower(std::string_view text) {
    std::string out(text);
    for (char& c : out) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
    return out;
  }
};

}  // namespace

std::string pack_frames(const Frames& frames) {
  std::size_t size = 4 + 4 * frames.size();
  for (const std::string& frame : frames) size += (frame.size() + 3) / 4 * 4;
  std::string out;
  out.reserve(size);
  append_u32(out, static_cast<std::uint32_t>(frames.size()));
  for (const std::string& frame : frames) append_u32(out, static_cast<std::uint32_t>(frame.size()));
  for (const std::string& frame : frames) {
    out += frame;
    out.append((4 - frame.size() % 4) % 4, '\0');
  }
  return out;
}

namespace view_detail {

class WsSession;
class HttpSession;

// The server's state, shared by its sessions (ViewServer::Impl is this, under a private name).
struct ServerCore {
  std::filesystem::path web_root;
  std::string url;
  ServedNames served;
  std::atomic<std::size_t> open_connections{0};  // WebSockets
  std::atomic<std::size_t> open_http{0};         // connections not (yet) a WebSocket
  std::atomic<std::uint64_t> replaced{0};
  std::atomic<std::uint64_t> evicted{0};
  std::atomic<std::uint64_t> refused_labels{0};

  // Messages posted and not yet handed to the connections; guarded by mutex, so that post()
  // only ever takes a short lock and never waits for the network.
  std::mutex mutex;
  Conflated inbox;
  bool drain_scheduled = false;

  // Only the server thread touches these.
  std::vector<std::weak_ptr<WsSession>> sessions;
  Conflated cache;  // the newest message of every topic, for pages that join late
  std::deque<std::weak_ptr<HttpSession>> http_sessions;  // oldest first

  // Declared last: destroyed first, with every connection, while the members above still live.
  asio::io_context ioc{1};
  tcp::acceptor acceptor{ioc};
  asio::steady_timer accept_pause{ioc};
  std::thread thread;

  void accept();
  void admit(tcp::socket socket);
  void drain();
  void count_refused_labels(std::uint64_t count);
  void add_session(const std::shared_ptr<WsSession>& session);
  std::size_t unsent();
};

}  // namespace view_detail

struct ViewServer::Impl : view_detail::ServerCore {};

namespace view_detail {

// One page's WebSocket: sends the newest message of each topic, one write at a time.
class WsSession : public std::enable_shared_from_this<WsSession> {
 public:
  WsSession(tcp::socket socket, ServerCore& server) : ws_(std::move(socket)), server_(server) {
    ++server_.open_connections;
  }
  ~WsSession() { --server_.open_connections; }

  void run(http::request<http::string_body> request) {
    // Pings at half the idle timeout: a page that only listens (browsers answer pings) stays
    // connected through a paused scan, and a vanished one is noticed.
    auto timeouts = websocket::stream_base::timeout::suggested(beast::role_type::server);
    timeouts.keep_alive_pings = true;
    ws_.set_option(timeouts);
    ws_.read_message_max(kMaxIncomingMessageBytes);
    ws_.binary(true);
    ws_.async_accept(request, [self = shared_from_this()](beast::error_code ec) {
      if (ec) return;
      self->server_.add_session(self);
      self->read();
    });
  }

  void enqueue(Item item) {
    server_.replaced += pending_.add(std::move(item));
    if (!writing_) write_next();
  }

  /// Messages queued or being written to this page.
  std::size_t unsent() const { return pending_.size() + (writing_ ? 1 : 0); }

 private:
  // The page sends nothing the server needs; reading keeps pings, pongs and the close
  // handshake going, and ends the session when the page goes.
  void read() {
    ws_.async_read(incoming_, [self = shared_from_this()](beast::error_code ec, std::size_t) {
      if (ec) return;
      self->incoming_.clear();
      self->read();
    });
  }

  void write_next() {
    if (pending_.empty()) {
      writing_ = false;
      return;
    }
    writing_ = true;
    current_ = pending_.pop_front();
    ws_.async_write(asio::buffer(*current_.packed),
                    [self = shared_from_this()](beast::error_code ec, std::size_t) {
                      self->current_ = {};
                      if (ec) return;  // the page went: the session ends with its handlers
                      self->write_next();
                    });
  }

  websocket::stream<beast::tcp_stream> ws_;
  ServerCore& server_;
  beast::flat_buffer incoming_;
  Conflated pending_;
  Item current_;
  bool writing_ = false;
};

// One HTTP connection: files for the page, or the upgrade to its WebSocket.
class HttpSession : public std::enable_shared_from_this<HttpSession> {
 public:
  HttpSession(tcp::socket socket, ServerCore& server)
      : stream_(std::move(socket)), server_(server) {
    ++server_.open_http;
  }
  ~HttpSession() { --server_.open_http; }

  void read() {
    parser_.emplace();
    parser_->header_limit(kMaxHeaderBytes);
    parser_->body_limit(kMaxRequestBytes);
    stream_.expires_after(kRequestTimeout);
    http::async_read(stream_, buffer_, *parser_,
                     [self = shared_from_this()](beast::error_code ec, std::size_t) {
                       if (ec) return;  // closed, timed out or malformed: drop the connection
                       self->on_request(self->parser_->release());
                     });
  }

  /// Whether the connection is still this session's (not closed, not handed to a WebSocket).
  bool open() const { return stream_.socket().is_open(); }

  /// Closes the connection: its pending read or write ends, and with it the session.
  void close() {
    beast::error_code ignored;
    stream_.socket().shutdown(tcp::socket::shutdown_both, ignored);
    stream_.close();
  }

 private:
  void on_request(http::request<http::string_body> request) {
    const std::string host(request[http::field::host]);
    if (!server_.served.allows(host))
      return respond(request, http::status::misdirected_request,
                     "this sonoshape view answers only for its own addresses (" + server_.url +
                         ", or localhost with the same port), not for Host '" +
                         host.substr(0, 100) +
                         "': a page of another site may not read the scan through a name "
                         "rebound to this machine\n");
    if (websocket::is_upgrade(request)) return upgrade(std::move(request));
    if (request.method() != http::verb::get && request.method() != http::verb::head)
      return respond(request, http::status::method_not_allowed, "GET only\n");
    const std::string target(request.target());
    const auto path = resolve_target(server_.web_root, target);
    // Only regular files: a folder (e.g. /three/build/) would be answered 200 with no body.
    beast::error_code ec;
    http::file_body::value_type body;
    if (path && check_input_file(*path, "page file"))
      body.open(path->c_str(), beast::file_mode::scan, ec);
    if (!path || !body.is_open() || ec) {
      const bool three = target.starts_with("/three/");
      return respond(
          request, http::status::not_found,
          three ? "three.js is not installed in viewer/node_modules: run "
                  "scripts/install-deps (it fetches the version viewer/package-lock.json pins)\n"
                : "not found\n");
    }
    // The file is read as the client takes it, a few kilobytes at a time: a client that does not
    // read holds no copy of it (issue 40, C2).
    auto response = std::make_shared<http::response<http::file_body>>(
        std::piecewise_construct, std::make_tuple(std::move(body)),
        std::make_tuple(http::status::ok, request.version()));
    decorate(*response, request, content_type(*path));
    response->prepare_payload();
    if (request.method() == http::verb::head) {
      auto head = std::make_shared<http::response<http::empty_body>>(response->base());
      return send(head);
    }
    send(response);
  }

  void upgrade(http::request<http::string_body> request) {
    // A page of another site open in the same browser must not read the scan: browsers
    // always send Origin with a WebSocket, and it must be a page this server served.
    const std::string origin(request[http::field::origin]);
    if (!server_.served.allows_origin(origin))
      return respond(request, http::status::forbidden,
                     "the viewer's WebSocket serves only its own page (Origin " + server_.url +
                         " or localhost with the same port), not Origin '" + origin.substr(0, 100) +
                         "'\n");
    if (server_.open_connections.load() >= kMaxPages)
      return respond(request, http::status::service_unavailable,
                     "this sonoshape view already streams to " + std::to_string(kMaxPages) +
                         " pages, its limit: close a page and reload this one\n");
    stream_.expires_never();
    std::make_shared<WsSession>(stream_.release_socket(), server_)->run(std::move(request));
  }

  template <class Response>
  void decorate(Response& response, const http::request<http::string_body>& request,
                std::string_view type) {
    response.set(http::field::server, "sonoshape");
    response.set(http::field::content_type, std::string(type));
    // The page changes with sonoshape: never run a stale copy.
    response.set(http::field::cache_control, "no-cache");
    response.set("X-Content-Type-Options", "nosniff");
    response.keep_alive(request.keep_alive());
  }

  void respond(const http::request<http::string_body>& request, http::status status,
               std::string body) {
    auto response = std::make_shared<http::response<http::string_body>>(status, request.version());
    decorate(*response, request, "text/plain");
    const bool head = request.method() == http::verb::head;
    response->body() = std::move(body);
    response->prepare_payload();
    if (head) response->body().clear();
    send(response);
  }

  // Writes `response` within kResponseTimeout, then reads the next request or closes.
  template <class Response>
  void send(const std::shared_ptr<Response>& response) {
    stream_.expires_after(kResponseTimeout);
    http::async_write(stream_, *response,
                      [self = shared_from_this(), response](beast::error_code ec, std::size_t) {
                        if (ec) return;
                        if (response->keep_alive()) return self->read();
                        beast::error_code ignored;
                        self->stream_.socket().shutdown(tcp::socket::shutdown_send, ignored);
                      });
  }

  beast::tcp_stream stream_;
  ServerCore& server_;
  // A request's headers and body at most: a client cannot make the buffer grow beyond.
  beast::flat_buffer buffer_{kMaxHeaderBytes + kMaxRequestBytes};
  std::optional<http::request_parser<http::string_body>> parser_;
};

void ServerCore::accept() {
  acceptor.async_accept([this](beast::error_code ec, tcp::socket socket) {
    if (ec == asio::error::operation_aborted) return;
    if (!ec) {
      admit(std::move(socket));
      return accept();
    }
    // Out of file descriptors (or another passing trouble): try again shortly instead of
    // spinning on an accept that fails at once.
    accept_pause.expires_after(std::chrono::milliseconds(100));
    accept_pause.async_wait([this](beast::error_code wait_ec) {
      if (wait_ec != asio::error::operation_aborted) accept();
    });
  });
}

// At kMaxConnections, the oldest connection that holds no WebSocket makes room: whoever floods
// the server with connections that send or read nothing closes its own first.
void ServerCore::admit(tcp::socket socket) {
  std::erase_if(http_sessions, [](const std::weak_ptr<HttpSession>& weak) {
    const auto session = weak.lock();
    return !session || !session->open();
  });
  if (http_sessions.size() + open_connections.load() >= kMaxConnections && !http_sessions.empty()) {
    if (const auto oldest = http_sessions.front().lock()) oldest->close();
    http_sessions.pop_front();
    ++evicted;
  }
  auto session = std::make_shared<HttpSession>(std::move(socket), *this);
  http_sessions.push_back(session);
  session->read();
}

void ServerCore::add_session(const std::shared_ptr<WsSession>& session) {
  std::erase_if(sessions, [](const std::weak_ptr<WsSession>& s) { return s.expired(); });
  sessions.push_back(session);
  for (const Item& item : cache.items()) session->enqueue(item);
}

void ServerCore::drain() {
  Conflated items;
  {
    const std::lock_guard lock(mutex);
    std::swap(items, inbox);
    drain_scheduled = false;
  }
  while (!items.empty()) {
    Item item = items.pop_front();
    std::uint64_t refused = 0;
    cache.add(item, &refused);
    if (refused) {
      count_refused_labels(refused);
      continue;
    }
    for (const std::weak_ptr<WsSession>& weak : sessions)
      if (const auto session = weak.lock()) session->enqueue(item);
  }
}

std::size_t ServerCore::unsent() {
  std::size_t count = 0;
  {
    const std::lock_guard lock(mutex);
    count += inbox.size() + (drain_scheduled ? 1 : 0);
  }
  for (const std::weak_ptr<WsSession>& weak : sessions)
    if (const auto session = weak.lock()) count += session->unsent();
  return count;
}

void ServerCore::count_refused_labels(std::uint64_t count) {
  if (refused_labels.fetch_add(count) == 0)
    log_warning("view: the stream carries more than " + std::to_string(kMaxStreamLabels) +
                " mesh labels in one scan; the meshes of further labels are not shown (counted; "
                "said once): a scan has at most " +
                std::to_string(kMaxStreamLabels) + " labels");
}

}  // namespace view_detail

ViewServer::ViewServer(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}
ViewServer::ViewServer(ViewServer&&) noexcept = default;
ViewServer& ViewServer::operator=(ViewServer&&) noexcept = default;

ViewServer::~ViewServer() {
  if (!impl_) return;
  impl_->ioc.stop();
  if (impl_->thread.joinable()) impl_->thread.join();
}

Result<ViewServer> ViewServer::start(const ViewServerOptions& options) {
  const std::string& address = options.http;
  const std::string fix = "; give --http HOST:PORT, e.g. 127.0.0.1:8080 (port 0 picks a free one)";
  const std::size_t colon = address.rfind(':');
  if (colon == std::string::npos || colon == 0 || colon + 1 == address.size())
    return Status::error("viewer address '" + address + "' is not HOST:PORT" + fix);
  std::string host = address.substr(0, colon);
  if (host.size() > 2 && host.front() == '[' && host.back() == ']')
    host = host.substr(1, host.size() - 2);
  if (host == "localhost") host = "127.0.0.1";
  unsigned long port = 0;
  const std::string port_text = address.substr(colon + 1);
  const auto digit = [](char c) { return std::isdigit(static_cast<unsigned char>(c)) != 0; };
  if (!std::all_of(port_text.begin(), port_text.end(), digit) || port_text.size() > 5 ||
      (port = std::stoul(port_text)) > 65535)
    return Status::error("viewer address '" + address + "' has no valid port" + fix);
  beast::error_code ec;
  const asio::ip::address ip = asio::ip::make_address(host, ec);
  if (ec)
    return Status::error("viewer address '" + address + "': '" + host +
                         "' is not an IP address of this machine" + fix);
  if (!std::filesystem::is_regular_file(options.web_root / "index.html"))
    return Status::error("the viewer's page is not in " + options.web_root.string() +
                         " (no index.html); give the viewer/ folder of the sonoshape sources "
                         "with --web-root");

  auto impl = std::make_unique<Impl>();
  impl->web_root = options.web_root;
  const tcp::endpoint endpoint(ip, static_cast<unsigned short>(port));
  impl->acceptor.open(endpoint.protocol(), ec);
  if (!ec) impl->acceptor.set_option(asio::socket_base::reuse_address(true), ec);
  if (!ec) impl->acceptor.bind(endpoint, ec);
  if (!ec) impl->acceptor.listen(asio::socket_base::max_listen_connections, ec);
  if (ec)
    return Status::error(
        "cannot serve the viewer on " + address + ": " + ec.message() +
        (ec == asio::error::address_in_use ? "; another program has the port" : "") + fix);
  const tcp::endpoint bound = impl->acceptor.local_endpoint();
  const std::string shown = ip.is_v6() ? "[" + host + "]" : host;
  impl->url = "http://" + shown + ":" + std::to_string(bound.port()) + "/";
  impl->served.port = bound.port();
  impl->served.names = {"127.0.0.1", "localhost", "[::1]", ServedNames::lower(shown)};
  impl->served.any_address = ip.is_unspecified();
  impl->accept();
  Impl* raw = impl.get();
  impl->thread = std::thread([raw] { raw->ioc.run(); });
  return ViewServer(std::move(impl));
}

void ViewServer::post(const Frames& frames) {
  if (frames.empty()) return;
  auto [scan, key] = scan_and_key(frames);
  Item item{frames[0], std::move(scan), std::make_shared<const std::string>(pack_frames(frames)),
            std::move(key)};
  bool schedule = false;
  std::uint64_t refused = 0;
  {
    const std::lock_guard lock(impl_->mutex);
    impl_->replaced += impl_->inbox.add(std::move(item), &refused);
    schedule = !impl_->drain_scheduled;
    impl_->drain_scheduled = true;
  }
  if (refused) impl_->count_refused_labels(refused);
  if (schedule) asio::post(impl_->ioc, [raw = impl_.get()] { raw->drain(); });
}

void ViewServer::post_stream_state(StreamState state, const std::string& endpoint,
                                   const std::string& message) {
  nlohmann::json header;
  header["stream"] = state == StreamState::kConnected  ? "connected"
                     : state == StreamState::kFinished ? "finished"
                                                       : "waiting";
  header["endpoint"] = endpoint;
  if (!message.empty()) header["message"] = message;
  post(Frames{std::string(kViewerTopic), header.dump()});
}

bool ViewServer::flush(std::chrono::milliseconds timeout) {
  const auto deadline = std::chrono::steady_clock::now() + timeout;
  while (true) {
    // Counted on the server thread, which alone touches the sessions.
    auto unsent = std::make_shared<std::promise<std::size_t>>();
    std::future<std::size_t> count = unsent->get_future();
    asio::post(impl_->ioc, [raw = impl_.get(), unsent] { unsent->set_value(raw->unsent()); });
    if (count.wait_until(deadline) != std::future_status::ready) return false;
    if (count.get() == 0) return true;
    if (std::chrono::steady_clock::now() >= deadline) return false;
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
  }
}

std::string ViewServer::url() const { return impl_->url; }

std::size_t ViewServer::connections() const { return impl_->open_connections.load(); }

std::uint64_t ViewServer::messages_replaced() const { return impl_->replaced.load(); }

std::size_t ViewServer::open_connections() const {
  return impl_->open_connections.load() + impl_->open_http.load();
}

std::uint64_t ViewServer::connections_closed_at_limit() const { return impl_->evicted.load(); }

std::uint64_t ViewServer::meshes_refused_over_label_limit() const {
  return impl_->refused_labels.load();
}

}  // namespace sonoshape::publish
