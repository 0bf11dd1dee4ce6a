!> Benchmark of spherical-harmonic evaluation (one thread):
!>   - synthesis of r on the full 120 x 240 Gauss grid at degree 14 and 30 (with and without the
!>     two angular derivatives),
!>   - single-point evaluation r(u) at random directions at degree 14 and 30 (the contact-test path).
!> Prints the median time over repeated batches. Run: bash scripts/bench.sh (see docs/performance.md).
program bench_sh
   use, intrinsic :: iso_fortran_env, only: output_unit
   use anm_core_kinds, only: wp, i8
   use anm_core_statistics, only: median
   use anm_core_random, only: rng_type, new_rng
   use anm_sh_expansion, only: sh_expansion_type, sh_truncate
   use anm_sh_grid, only: sh_grid_type, new_sh_grid, sh_synthesize
   use anm_shapes_synthetic, only: synthetic_params_type, make_synthetic_shape
   use anm_core_error, only: error_type
   implicit none
   type(synthetic_params_type) :: par
   type(sh_expansion_type) :: full, s
   type(sh_grid_type) :: grid
   type(error_type), allocatable :: error
   integer :: degrees(2), id

   par%nmax = 30
   call make_synthetic_shape(par, 1_i8, 1, full, error)
   if (allocated(error)) error stop "synthetic shape"
   grid = new_sh_grid(120, 240, 30)
   degrees = [14, 30]
   write (output_unit, '(a)') "# SH evaluation benchmark, 1 thread; times are medians over 15 batches"
   do id = 1, 2
      s = sh_truncate(full, degrees(id))
      call bench_grid(s, degrees(id))
      call bench_points(s, degrees(id))
   end do

contains

   real(wp) function wall()
      integer(i8) :: c, r
      call system_clock(c, r)
      wall = real(c, wp) / real(r, wp)
   end function wall

   subroutine bench_grid(s, deg)
      type(sh_expansion_type), intent(in) :: s
      integer, intent(in) :: deg
      real(wp), allocatable :: r(:, :), rt(:, :), rp(:, :)
      real(wp) :: times(15), times_d(15), t0, sink
      integer :: b, k, nrep
      allocate (r(120, 240), rt(120, 240), rp(120, 240))
      nrep = 200
      sink = 0
      do b = 1, 15
         t0 = wall()
         do k = 1, nrep
            call sh_synthesize(grid, s, r)
            sink = sink + r(1 + mod(k, 120), 1)
         end do
         times(b) = (wall() - t0) / nrep
         t0 = wall()
         do k = 1, nrep / 4
            call sh_synthesize(grid, s, r, rt, rp)
            sink = sink + rt(1 + mod(k, 120), 1)
         end do
         times_d(b) = (wall() - t0) / (nrep / 4)
      end do
      write (output_unit, '(a,i0,a,f8.4,a,f8.4,a,es9.2,a)') "grid 120x240 degree ", deg, ": r only ", &
         1.0e3_wp * median(times), " ms; r + dr/dtheta + dr/dphi/sin ", 1.0e3_wp * median(times_d), &
         " ms   (checksum ", sink, ")"
   end subroutine bench_grid

   subroutine bench_points(s, deg)
      type(sh_expansion_type), intent(in) :: s
      integer, intent(in) :: deg
      integer, parameter :: npt = 100000
      real(wp), allocatable :: u(:, :)
      real(wp) :: times(15), t0, sink
      type(rng_type) :: rng
      integer :: b, k
      call new_rng(rng, 3_i8, 0_i8)
      allocate (u(3, npt))
      do k = 1, npt
         u(:, k) = [rng%normal(), rng%normal(), rng%normal()]
         u(:, k) = u(:, k) / norm2(u(:, k))
      end do
      sink = 0
      do b = 1, 15
         t0 = wall()
         do k = 1, npt
            sink = sink + s%radius_dir(u(:, k))
         end do
         times(b) = (wall() - t0) / npt
      end do
      write (output_unit, '(a,i0,a,f8.1,a,f6.1,a,es9.2,a)') "single points degree ", deg, ": ", &
         1.0e-6_wp / median(times), " million points/s (", 1.0e9_wp * median(times), " ns/point)   (checksum ", &
         sink, ")"
   end subroutine bench_points

end program bench_sh
