!> Thread-safe pseudo-random numbers: xoshiro256** whose state is a derived type passed
!> explicitly, seeded per stream from (seed, stream id) through splitmix64.
!>
!> Streams with different ids are statistically independent, so a parallel loop gives each work
!> item (or thread) its own stream and results do not depend on scheduling.
!> All 64-bit arithmetic is done modulo 2**64 without signed overflow (Fortran has no unsigned
!> integers), so the sequence is identical on every compiler and optimisation level.
!>
!> Usage:
!>     type(rng_type) :: rng
!>     call new_rng(rng, seed=42_i8, stream=7_i8)
!>     u = rng%uniform()          ! in [0, 1)
!>     g = rng%normal()           ! standard normal
module anm_core_random
   use anm_core_kinds, only: wp, i8, two_pi
   implicit none
   private

   public :: rng_type, new_rng, splitmix64, wrapping_add, wrapping_mul

   !> State of one xoshiro256** stream.
   type :: rng_type
      private
      integer(i8) :: s(4) = [1_i8, 2_i8, 3_i8, 4_i8]
      !> Second normal deviate kept from the polar method (valid when has_spare).
      real(wp) :: spare = 0.0_wp
      logical :: has_spare = .false.
   contains
      !> Next raw 64-bit output.
      procedure :: next_int64
      !> Uniform deviate in [0, 1).
      procedure :: uniform
      !> Uniform deviate in [lo, hi).
      procedure :: uniform_range
      !> Standard normal deviate.
      procedure :: normal
      !> Uniform integer in [1, n].
      procedure :: below
   end type rng_type

   integer(i8), parameter :: mask32 = 4294967295_i8, mask16 = 65535_i8
   ! splitmix64 constants 0x9E3779B97F4A7C15, 0xBF58476D1CE4E5B9, 0x94D049BB133111EB as signed
   integer(i8), parameter :: golden = -7046029254386353131_i8
   integer(i8), parameter :: mix1 = -4658895280553007687_i8
   integer(i8), parameter :: mix2 = -7723592293110705685_i8

contains

   !> Seed a stream from a base seed and a stream id (any values, including 0 and negatives).
   pure subroutine new_rng(rng, seed, stream)
      !> Generator to initialise.
      type(rng_type), intent(out) :: rng
      !> Base seed (the namelist seed).
      integer(i8), intent(in) :: seed
      !> Stream id (thread, particle or work-item number).
      integer(i8), intent(in) :: stream
      integer(i8) :: x, h
      integer :: i
      ! Hash the stream id and combine with the seed so that (seed, stream) pairs map to
      ! well-separated splitmix64 starting points.
      x = stream
      call splitmix64(x, h)
      x = ieor(seed, h)
      do i = 1, 4
         call splitmix64(x, rng%s(i))
      end do
      if (all(rng%s == 0_i8)) rng%s(1) = 1_i8
      rng%has_spare = .false.
   end subroutine new_rng

   !> splitmix64: advance `x` by the golden-ratio increment and return the mixed value in `z`.
   pure subroutine splitmix64(x, z)
      !> State, advanced in place.
      integer(i8), intent(inout) :: x
      !> Output.
      integer(i8), intent(out) :: z
      x = wrapping_add(x, golden)
      z = x
      z = wrapping_mul(ieor(z, ishft(z, -30)), mix1)
      z = wrapping_mul(ieor(z, ishft(z, -27)), mix2)
      z = ieor(z, ishft(z, -31))
   end subroutine splitmix64

   !> (a + b) modulo 2**64 on the two's-complement bit patterns, without signed overflow.
   elemental function wrapping_add(a, b) result(c)
      !> Summands.
      integer(i8), intent(in) :: a, b
      integer(i8) :: c
      integer(i8) :: lo, hi
      lo = iand(a, mask32) + iand(b, mask32)
      hi = iand(ishft(a, -32), mask32) + iand(ishft(b, -32), mask32) + ishft(lo, -32)
      c = ior(ishft(iand(hi, mask32), 32), iand(lo, mask32))
   end function wrapping_add

   !> (a * b) modulo 2**64 on the two's-complement bit patterns, from products of 32- and 16-bit
   !> limbs that never overflow a signed 64-bit integer.
   elemental function wrapping_mul(a, b) result(c)
      !> Factors.
      integer(i8), intent(in) :: a, b
      integer(i8) :: c, al, ah, bl, bh, lo, cross
      al = iand(a, mask32)
      ah = iand(ishft(a, -32), mask32)
      bl = iand(b, mask32)
      bh = iand(ishft(b, -32), mask32)
      ! al * bl in full (64 bits): split al into 16-bit halves
      lo = wrapping_add(ishft(ishft(al, -16) * bl, 16), iand(al, mask16) * bl)
      ! the cross terms only matter modulo 2**32
      cross = iand(mulmod32(ah, bl) + mulmod32(al, bh), mask32)
      c = wrapping_add(lo, ishft(cross, 32))
   contains
      elemental function mulmod32(x, y) result(z)
         integer(i8), intent(in) :: x, y
         integer(i8) :: z
         z = iand(ishft(iand(ishft(x, -16) * y, mask16), 16) + iand(x, mask16) * y, mask32)
      end function mulmod32
   end function wrapping_mul

   !> Next 64 random bits (xoshiro256**).
   function next_int64(self) result(res)
      !> Generator.
      class(rng_type), intent(inout) :: self
      integer(i8) :: res, t, s1x5
      ! result = rotl(s1 * 5, 7) * 9, multiplications as shift + add
      s1x5 = wrapping_add(ishft(self%s(2), 2), self%s(2))
      t = ishftc(s1x5, 7)
      res = wrapping_add(ishft(t, 3), t)
      t = ishft(self%s(2), 17)
      self%s(3) = ieor(self%s(3), self%s(1))
      self%s(4) = ieor(self%s(4), self%s(2))
      self%s(2) = ieor(self%s(2), self%s(3))
      self%s(1) = ieor(self%s(1), self%s(4))
      self%s(3) = ieor(self%s(3), t)
      self%s(4) = ishftc(self%s(4), 45)
   end function next_int64

   !> Uniform deviate in [0, 1) with 53 random bits.
   function uniform(self) result(u)
      !> Generator.
      class(rng_type), intent(inout) :: self
      real(wp) :: u
      u = real(ishft(self%next_int64(), -11), wp) * 2.0_wp**(-53)
   end function uniform

   !> Uniform deviate in [lo, hi).
   function uniform_range(self, lo, hi) result(u)
      !> Generator.
      class(rng_type), intent(inout) :: self
      !> Interval bounds.
      real(wp), intent(in) :: lo, hi
      real(wp) :: u
      u = lo + (hi - lo) * self%uniform()
   end function uniform_range

   !> Standard normal deviate (Box-Muller, both values used).
   function normal(self) result(g)
      !> Generator.
      class(rng_type), intent(inout) :: self
      real(wp) :: g
      real(wp) :: u1, u2, rad
      if (self%has_spare) then
         self%has_spare = .false.
         g = self%spare
         return
      end if
      u1 = 1.0_wp - self%uniform()   ! in (0, 1]
      u2 = self%uniform()
      rad = sqrt(-2.0_wp * log(u1))
      g = rad * cos(two_pi * u2)
      self%spare = rad * sin(two_pi * u2)
      self%has_spare = .true.
   end function normal

   !> Uniform integer in [1, n] (n >= 1); bias below n / 2**53.
   function below(self, n) result(k)
      !> Generator.
      class(rng_type), intent(inout) :: self
      !> Upper bound.
      integer, intent(in) :: n
      integer :: k
      k = min(n, 1 + int(self%uniform() * real(n, wp)))
   end function below
end module anm_core_random
