#pragma once

#include <algorithm>
#include <atomic>
#include <cstdint>
#include <initializer_list>
#include <functional>
#include <sstream>
#include <string>
#include <unordered_set>
#include <utility>
#include <vector>

namespace prime {

// What a topology is made of, for people: every chain, source and combinator
// carries the graph of what it was built from, and prints it as text or as
// Graphviz DOT. Built while linking, never touched on the data path.
class Graph {
 public:
  struct Node {
    std::uint64_t id;
    std::string name;
    std::string kind;    // "chain", "source", "collector", "sync", ...
    std::string medium;  // "liberty", "radiant", ...
  };
  struct Edge {
    std::uint64_t from;
    std::uint64_t to;
    friend bool operator==(const Edge&, const Edge&) = default;
  };

  Graph() = default;

  // One node that is both where data enters and where it leaves.
  static Graph node(std::string name, std::string kind, std::string medium) {
    static std::atomic<std::uint64_t> next_id{1};
    Graph g;
    const auto id = next_id.fetch_add(1, std::memory_order_relaxed);
    g.nodes_.push_back({id, std::move(name), std::move(kind), std::move(medium)});
    g.entries_ = {id};
    g.exits_ = {id};
    return g;
  }

  // `first` feeds `second`: every exit of one is joined to every entry of the other.
  static Graph sequence(const Graph& first, const Graph& second) {
    Graph g = first;
    g.absorb(second);
    for (auto from : first.exits_)
      for (auto to : second.entries_) g.add_edge({from, to});
    g.entries_ = first.entries_;
    g.exits_ = second.exits_;
    return g;
  }

  // Side by side: data may enter or leave through any of the parts.
  static Graph parallel(std::initializer_list<const Graph*> parts) {
    Graph g;
    for (const Graph* part : parts) {
      g.absorb(*part);
      append_unique(g.entries_, part->entries_);
      append_unique(g.exits_, part->exits_);
    }
    return g;
  }

  // An edge back from this graph's exits to `target`'s entries (a loop).
  [[nodiscard]] Graph looping_back_to(const Graph& target) const {
    Graph g = *this;
    for (auto from : exits_)
      for (auto to : target.entries_) g.add_edge({from, to});
    return g;
  }

  [[nodiscard]] const std::vector<Node>& nodes() const noexcept { return nodes_; }
  [[nodiscard]] const std::vector<Edge>& edges() const noexcept { return edges_; }
  [[nodiscard]] const std::vector<std::uint64_t>& entries() const noexcept { return entries_; }
  [[nodiscard]] const std::vector<std::uint64_t>& exits() const noexcept { return exits_; }

  // "lidar [source, liberty] -> localize [chain, radiant]", one edge a line,
  // then any node that has no edge. Names that repeat get a "#id" suffix.
  [[nodiscard]] std::string text() const {
    std::ostringstream out;
    std::vector<std::uint64_t> linked;
    for (const auto& e : edges_) {
      out << label(e.from) << " -> " << label(e.to) << '\n';
      linked.push_back(e.from);
      linked.push_back(e.to);
    }
    for (const auto& n : nodes_)
      if (std::ranges::find(linked, n.id) == linked.end()) out << label(n.id) << '\n';
    return out.str();
  }

  [[nodiscard]] std::string dot() const {
    std::ostringstream out;
    out << "digraph prime {\n  rankdir=LR;\n";
    for (const auto& n : nodes_) {
      out << "  n" << n.id << " [label=\"" << escaped(n.name) << "\\n" << escaped(n.kind) << ", "
          << escaped(n.medium) << "\", shape=" << shape(n.kind) << "];\n";
    }
    for (const auto& e : edges_) out << "  n" << e.from << " -> n" << e.to << ";\n";
    out << "}\n";
    return out.str();
  }

 private:
  // Linear in the size of both graphs, so a chain of n links builds in O(n^2).
  void absorb(const Graph& other) {
    std::unordered_set<std::uint64_t> known;
    for (const auto& n : nodes_) known.insert(n.id);
    for (const auto& n : other.nodes_)
      if (known.insert(n.id).second) nodes_.push_back(n);
    std::unordered_set<Edge, EdgeHash> edges(edges_.begin(), edges_.end());
    for (const auto& e : other.edges_)
      if (edges.insert(e).second) edges_.push_back(e);
  }
  void add_edge(Edge e) {
    if (std::ranges::find(edges_, e) == edges_.end()) edges_.push_back(e);
  }
  struct EdgeHash {
    std::size_t operator()(const Edge& e) const noexcept { return std::hash<std::uint64_t>{}(e.from * 0x9E3779B97F4A7C15ull ^ e.to); }
  };
  static void append_unique(std::vector<std::uint64_t>& to, const std::vector<std::uint64_t>& from) {
    for (auto id : from)
      if (std::ranges::find(to, id) == to.end()) to.push_back(id);
  }
  [[nodiscard]] const Node* find(std::uint64_t id) const {
    auto it = std::ranges::find(nodes_, id, &Node::id);
    return it == nodes_.end() ? nullptr : &*it;
  }
  [[nodiscard]] std::string label(std::uint64_t id) const {
    const Node* n = find(id);
    const auto same_name = std::ranges::count(nodes_, n->name, &Node::name);
    std::string name = n->name;
    if (same_name > 1) name.append("#").append(std::to_string(n->id));
    return name + " [" + n->kind + ", " + n->medium + "]";
  }
  static std::string escaped(const std::string& s) {
    std::string r;
    for (char c : s) {
      if (c == '"' || c == '\\') r += '\\';
      r += c;
    }
    return r;
  }
  static const char* shape(const std::string& kind) {
    if (kind == "source") return "ellipse";
    if (kind == "sync" || kind == "collector" || kind == "fork") return "diamond";
    return "box";
  }

  std::vector<Node> nodes_;
  std::vector<Edge> edges_;
  std::vector<std::uint64_t> entries_;
  std::vector<std::uint64_t> exits_;
};

}  // namespace prime
