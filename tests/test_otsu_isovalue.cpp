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

// 8- and 16-bit integers are counted value by value, then binned; every other type sample by
// sample. Both must give the same histogram: each integer volume against its float32 copy (whose
// values are the same numbers), a 3-D view with several planes so that threads split it.
template <class T>
void expect_same_histogram_as_float(ScalarType type, std::int64_t lo, std::int64_t hi) {
  const Index3 dims{37, 11, 23};
  std::vector<T> v(static_cast<std::size_t>(dims[0] * dims[1] * dims[2]));
  std::vector<float> f(v.size());
  std::uint64_t state = 12345;
  for (std::size_t i = 0; i < v.size(); ++i) {
    state = state * 6364136223846793005u + 1442695040888963407u;
    // Clustered values with the ends of the type's range among them.
    const std::int64_t span = hi - lo + 1;
    std::int64_t x =
        lo + static_cast<std::int64_t>((state >> 33) % static_cast<std::uint64_t>(span));
    if (i % 7 == 0) x = (i % 14 == 0) ? lo : hi;
    if (i % 5 == 0) x = lo + span / 3;
    v[i] = static_cast<T>(x);
    f[i] = static_cast<float>(v[i]);
  }
  const ValueHistogram a = value_histogram(dense_view(v.data(), type, dims));
  const ValueHistogram b = value_histogram(dense_view(f.data(), ScalarType::Float32, dims));
  EXPECT_EQ(a.samples, v.size());
  EXPECT_EQ(a.samples, b.samples);
  EXPECT_EQ(a.min, b.min);
  EXPECT_EQ(a.max, b.max);
  EXPECT_EQ(a.count, b.count);
  EXPECT_EQ(a.lo, b.lo);
  EXPECT_EQ(a.hi, b.hi);
  EXPECT_EQ(otsu_isovalue(a), otsu_isovalue(b));
}

TEST(OtsuIsovalue, SmallIntegersCountedByValueGiveTheSampleBySampleHistogram) {
  expect_same_histogram_as_float<std::uint8_t>(ScalarType::UInt8, 0, 255);
  expect_same_histogram_as_float<std::int8_t>(ScalarType::Int8, -128, 127);
  expect_same_histogram_as_float<std::uint16_t>(ScalarType::UInt16, 0, 65535);
  expect_same_histogram_as_float<std::int16_t>(ScalarType::Int16, -32768, 32767);
  expect_same_histogram_as_float<std::int16_t>(ScalarType::Int16, -1200, 3000);
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
