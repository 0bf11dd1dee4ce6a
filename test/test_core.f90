!> Tests of the foundations: errors, the random number generator (published reference outputs
!> of splitmix64 and xoshiro256**, stream independence, uniformity).
module test_core
   use anm_core_kinds, only: wp, i8
   use anm_core_error, only: error_type, fatal_error, error_code
   use anm_core_random, only: rng_type, new_rng, splitmix64, wrapping_add, wrapping_mul
   use anm_testing, only: unittest_type, new_unittest, check
   implicit none
   private
   public :: collect_core

contains

   !> Tests of this suite.
   subroutine collect_core(tests)
      type(unittest_type), allocatable, intent(out) :: tests(:)
      tests = [ &
              new_unittest("fatal_error carries message and class", test_error), &
              new_unittest("splitmix64 reference output", test_splitmix_reference), &
              new_unittest("xoshiro256** reference output", test_xoshiro_reference), &
              new_unittest("wrapping arithmetic modulo 2**64", test_wrapping), &
              new_unittest("same seed and stream give the same sequence", test_reproducible), &
              new_unittest("streams are uncorrelated", test_streams), &
              new_unittest("uniform moments and normal moments", test_moments), &
              new_unittest("check fails on mismatch", test_check_fails, should_fail=.true.)]
   end subroutine collect_core

   subroutine test_error(error)
      type(error_type), allocatable, intent(out) :: error
      type(error_type), allocatable :: e
      call fatal_error(e, "file.dat:3: bad", error_code%format)
      call check(error, allocated(e), "error allocated")
      if (allocated(error)) return
      call check(error, e%message == "file.dat:3: bad" .and. e%stat == error_code%format, "message/class")
   end subroutine test_error

   subroutine test_splitmix_reference(error)
      type(error_type), allocatable, intent(out) :: error
      integer(i8) :: x, z
      ! splitmix64 from state 0: 0xE220A8397B1DCDAF, 0x6E789E6AA1B965F4 (Vigna's reference code)
      x = 0_i8
      call splitmix64(x, z)
      call check(error, z == -2152535657050944081_i8, "first output")
      if (allocated(error)) return
      call splitmix64(x, z)
      call check(error, z == 7960286522194355700_i8, "second output")
   end subroutine test_splitmix_reference

   subroutine test_xoshiro_reference(error)
      type(error_type), allocatable, intent(out) :: error
      type(rng_type) :: rng   ! default state (1, 2, 3, 4)
      integer(i8) :: expected(4), got
      integer :: i
      ! xoshiro256** reference implementation from state {1, 2, 3, 4}
      expected = [11520_i8, 0_i8, 1509978240_i8, 1215971899390074240_i8]
      do i = 1, 4
         got = rng%next_int64()
         call check(error, got == expected(i), "output "//achar(48 + i))
         if (allocated(error)) return
      end do
   end subroutine test_xoshiro_reference

   subroutine test_wrapping(error)
      type(error_type), allocatable, intent(out) :: error
      ! 2**63 - 1 + 1 wraps to -2**63; (-1) * (-1) = 1; 2**32 * 2**32 = 0 mod 2**64
      call check(error, wrapping_add(huge(1_i8), 1_i8) == -huge(1_i8) - 1_i8, "add wraps")
      if (allocated(error)) return
      call check(error, wrapping_mul(-1_i8, -1_i8) == 1_i8, "mul of -1")
      if (allocated(error)) return
      call check(error, wrapping_mul(4294967296_i8, 4294967296_i8) == 0_i8, "mul wraps")
      if (allocated(error)) return
      call check(error, wrapping_mul(123456789_i8, 987654321_i8) == 121932631112635269_i8, "small product")
   end subroutine test_wrapping

   subroutine test_reproducible(error)
      type(error_type), allocatable, intent(out) :: error
      type(rng_type) :: a, b, c
      integer :: i
      logical :: same, differ
      call new_rng(a, 42_i8, 7_i8)
      call new_rng(b, 42_i8, 7_i8)
      call new_rng(c, 43_i8, 7_i8)
      same = .true.
      differ = .false.
      do i = 1, 1000
         if (a%uniform() /= b%uniform()) same = .false.
      end do
      call new_rng(a, 42_i8, 7_i8)
      do i = 1, 10
         if (a%next_int64() /= c%next_int64()) differ = .true.
      end do
      call check(error, same, "same (seed, stream) must repeat")
      if (allocated(error)) return
      call check(error, differ, "different seed must differ")
   end subroutine test_reproducible

   subroutine test_streams(error)
      type(error_type), allocatable, intent(out) :: error
      integer, parameter :: nstream = 16, n = 20000
      type(rng_type) :: rng(nstream)
      real(wp) :: u(n, nstream), corr, ui(n), uj(n)
      integer :: i, j, k
      do i = 1, nstream
         call new_rng(rng(i), 2024_i8, int(i - 1, i8))
         do k = 1, n
            u(k, i) = rng(i)%uniform()
         end do
      end do
      ! neighbouring stream ids: correlation of the sequences ~ N(0, 1/n); 5 sigma bound
      do i = 1, nstream
         do j = i + 1, nstream
            ui = u(:, i) - 0.5_wp
            uj = u(:, j) - 0.5_wp
            corr = sum(ui * uj) / sqrt(sum(ui**2) * sum(uj**2))
            call check(error, abs(corr) < 5.0_wp / sqrt(real(n, wp)), "streams correlated")
            if (allocated(error)) return
         end do
      end do
   end subroutine test_streams

   subroutine test_moments(error)
      type(error_type), allocatable, intent(out) :: error
      type(rng_type) :: rng
      integer, parameter :: n = 200000
      real(wp) :: s1, s2, g1, g2, u, g
      integer :: k
      call new_rng(rng, 1_i8, 0_i8)
      s1 = 0; s2 = 0; g1 = 0; g2 = 0
      do k = 1, n
         u = rng%uniform()
         g = rng%normal()
         s1 = s1 + u
         s2 = s2 + u * u
         g1 = g1 + g
         g2 = g2 + g * g
      end do
      ! mean 1/2 (sd of estimate 0.29/sqrt(n)), E u^2 = 1/3, normal mean 0 and variance 1; 5 sigma
      call check(error, s1 / n, 0.5_wp, "uniform mean", thr=5 * 0.2887_wp / sqrt(real(n, wp)))
      if (allocated(error)) return
      call check(error, s2 / n, 1.0_wp / 3.0_wp, "uniform 2nd moment", thr=5 * 0.2981_wp / sqrt(real(n, wp)))
      if (allocated(error)) return
      call check(error, g1 / n, 0.0_wp, "normal mean", thr=5.0_wp / sqrt(real(n, wp)))
      if (allocated(error)) return
      call check(error, g2 / n, 1.0_wp, "normal variance", thr=5 * sqrt(2.0_wp) / sqrt(real(n, wp)))
   end subroutine test_moments

   subroutine test_check_fails(error)
      type(error_type), allocatable, intent(out) :: error
      call check(error, 1.0_wp, 1.1_wp, "deliberate mismatch", rel=1.0e-3_wp)
   end subroutine test_check_fails
end module test_core
