// How a topology describes itself.
#include <gtest/gtest.h>

#include "prime/topology/graph.hpp"

namespace prime::test {
namespace {

TEST(GraphTest, SequenceJoinsExitsToEntries) {
  auto a = Graph::node("a", "chain", "liberty");
  auto b = Graph::node("b", "chain", "radiant");
  auto ab = Graph::sequence(a, b);
  EXPECT_EQ(ab.nodes().size(), 2u);
  ASSERT_EQ(ab.edges().size(), 1u);
  EXPECT_EQ(ab.entries(), a.entries());
  EXPECT_EQ(ab.exits(), b.exits());
  EXPECT_EQ(ab.text(), "a [chain, liberty] -> b [chain, radiant]\n");
}

TEST(GraphTest, SharedPartsAppearOnce) {
  auto source = Graph::node("lidar", "source", "liberty");
  auto left = Graph::sequence(source, Graph::node("filter", "chain", "liberty"));
  auto right = Graph::sequence(source, Graph::node("log", "chain", "liberty"));
  auto joined = Graph::sequence(Graph::parallel({&left, &right}), Graph::node("sync", "sync", "liberty"));
  EXPECT_EQ(joined.nodes().size(), 4u) << joined.text();
  EXPECT_EQ(joined.entries().size(), 1u) << "the shared source is one entry";
  EXPECT_EQ(joined.edges().size(), 4u) << joined.text();
}

TEST(GraphTest, RepeatedNamesAreToldApart) {
  auto a = Graph::node("step", "chain", "liberty");
  auto b = Graph::node("step", "chain", "liberty");
  const auto text = Graph::sequence(a, b).text();
  EXPECT_NE(text.find("step#" + std::to_string(a.nodes()[0].id)), std::string::npos) << text;
  EXPECT_NE(text.find("step#" + std::to_string(b.nodes()[0].id)), std::string::npos) << text;
}

TEST(GraphTest, ALongChainIsDescribedAndReleasedWithoutRecursion) {
  Graph chain = Graph::node("step", "chain", "liberty");
  for (int i = 1; i < 100'000; ++i) chain = Graph::sequence(chain, Graph::node("step", "chain", "liberty"));
  EXPECT_EQ(chain.nodes().size(), 100'000u);
  EXPECT_EQ(chain.edges().size(), 99'999u);
}

TEST(GraphTest, TheEmptyGraphJoinsToNothing) {
  auto a = Graph::node("a", "chain", "liberty");
  EXPECT_EQ(Graph::sequence(Graph{}, a).text(), a.text());
  EXPECT_EQ(Graph::sequence(a, Graph{}).text(), a.text());
  EXPECT_EQ(Graph{}.text(), "");
}

TEST(GraphTest, LoneNodesAreListed) { EXPECT_EQ(Graph::node("x", "source", "m").text(), "x [source, m]\n"); }

TEST(GraphTest, DotQuotesNamesAndLinksNodes) {
  auto g = Graph::sequence(Graph::node("say \"hi\"", "source", "liberty"), Graph::node("b", "chain", "liberty"));
  const auto dot = g.dot();
  EXPECT_NE(dot.find(R"(label="say \"hi\"\nsource, liberty", shape=ellipse)"), std::string::npos) << dot;
  const auto from = g.nodes()[0].id, to = g.nodes()[1].id;
  EXPECT_NE(dot.find("n" + std::to_string(from) + " -> n" + std::to_string(to) + ";"), std::string::npos) << dot;
}

TEST(GraphTest, LoopBackAddsAnEdgeToTheStart) {
  auto loop = Graph::node("repeat", "repeat", "liberty");
  auto body = Graph::node("step", "chain", "liberty");
  auto g = Graph::sequence(loop, body).looping_back_to(loop);
  EXPECT_EQ(g.edges().size(), 2u);
  EXPECT_NE(g.text().find("step [chain, liberty] -> repeat [repeat, liberty]"), std::string::npos);
}

}  // namespace
}  // namespace prime::test
