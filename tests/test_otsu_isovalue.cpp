// --iso auto's rule (core/volume/otsu_isovalue.h): Otsu's threshold on hand-made volumes whose
// answer is known, merging in any order, and the volumes that have no threshold.
#include <gtest/gtest.h>

#include <cstdint>
#include <vector>

#include "core/errors.h"
#include "core/volume/otsu_isovalue.h"
#include "core/volume/volume.h"

namespace isotile {
namespace {

template <class T>
ValueHistogram histogram_of(std::vector<T>& v, ScalarType type) {
  return value_histogram(dense_view(v.data(), type, {static_cast<std::int64_t>(v.size()), 1, 1}));
}

TEST(OtsuIsovalue, TwoValuesSplitHalfwayBetweenThem) {
  std::vector<std::uint8_t> v(1000, 10);
  for (std::size_t i = 0; i < 300; ++i) v[i] = 200;
  const ValueHistogram h = histogram_of(v, ScalarType::UInt8);
  EXPECT_EQ(h.samples, 1000u);
  EXPECT_EQ(h.min, 10);
  EXPECT_EQ(h.max, 200);
  EXPECT_DOUBLE_EQ(otsu_isovalue(h), 105.0);
}

TEST(OtsuIsovalue, TwoClustersSplitBetweenThemNotAtTheMean) {
  // 900 samples around 100, 100 around 1000: the mean (190) lies inside the big cluster's tail
  // side; Otsu's threshold separates the clusters.
  std::vector<float> v;
  for (int i = 0; i < 900; ++i) v.push_back(95.0f + static_cast<float>(i % 11));
  for (int i = 0; i < 100; ++i) v.push_back(990.0f + static_cast<float>(i % 21));
  const double t = otsu_isovalue(histogram_of(v, ScalarType::Float32));
  EXPECT_GT(t, 105.0);
  EXPECT_LT(t, 990.0);
  // No sample equals the threshold, so no crossing sits on a sample.
  for (float x : v) EXPECT_NE(static_cast<double>(x), t);
}

TEST(OtsuIsovalue, NegativeValuesOrderBelowPositiveOnes) {
  std::vector<std::int16_t> v(2000, -1000);
  for (std::size_t i = 0; i < 1000; ++i) v[i] = 40;
  const double t = otsu_isovalue(histogram_of(v, ScalarType::Int16));
  EXPECT_DOUBLE_EQ(t, -480.0);
}

TEST(OtsuIsovalue, HistogramsOfPartsMergeIntoTheWhole) {
  std::vector<std::uint16_t> v(4096);
  for (std::size_t i = 0; i < v.size(); ++i) v[i] = static_cast<std::uint16_t>((i * 7919) % 3001);
  const ValueHistogram whole = histogram_of(v, ScalarType::UInt16);
  std::vector<std::uint16_t> a(v.begin(), v.begin() + 1000), b(v.begin() + 1000, v.end());
  ValueHistogram merged = histogram_of(b, ScalarType::UInt16);
  merge(merged, histogram_of(a, ScalarType::UInt16));
  EXPECT_EQ(merged.count, whole.count);
  EXPECT_EQ(merged.lo, whole.lo);
  EXPECT_EQ(merged.hi, whole.hi);
  EXPECT_EQ(merged.samples, whole.samples);
  EXPECT_EQ(otsu_isovalue(merged), otsu_isovalue(whole));
  EXPECT_GT(otsu_isovalue(whole), whole.min);
  EXPECT_LT(otsu_isovalue(whole), whole.max);
}

TEST(OtsuIsovalue, AConstantVolumeHasNoThreshold) {
  std::vector<float> v(64, 3.5f);
  try {
    otsu_isovalue(histogram_of(v, ScalarType::Float32));
    FAIL() << "no error for a constant volume";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("every sample is 3.5"), std::string::npos) << e.what();
  }
  EXPECT_THROW(otsu_isovalue(ValueHistogram{}), InputError);
}

TEST(OtsuIsovalue, ValuesWithinOneBinAreSplitInTheMiddle) {
  std::vector<float> v{1.0f, 1.0f, 1.0001f, 1.0001f};
  const double t = otsu_isovalue(histogram_of(v, ScalarType::Float32));
  EXPECT_GT(t, 1.0);
  EXPECT_LT(t, static_cast<double>(1.0001f));
}

}  // namespace
}  // namespace isotile
