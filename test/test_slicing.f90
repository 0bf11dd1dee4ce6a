!> Tests of the slicing kernel: plane validation, exact areas of sphere sections (with a periodic
!> image across a box face), shell layers grown at slicing time, and the labelling rules.
module test_slicing
   use anm_core_kinds, only: wp, pi, i8
   use anm_core_error, only: error_type
   use anm_core_random, only: rng_type, new_rng
   use anm_core_strings, only: to_string
   use anm_sh_expansion, only: sh_expansion_type, new_sh_expansion, new_sh_expansion_real
   use anm_slicing_plane, only: slice_plane_type, new_slice_plane, new_axis_plane, pixel_center
   use anm_slicing_form, only: slice_form_type, new_slice_form
   use anm_slicing_kernel, only: slice_labels, slice_stats_type
   use anm_slicing_shells, only: build_shell_forms
   use anm_slicing_stack, only: slice_stack_type, new_slice_stack, stack_radii, build_stack_table, &
      & stack_table_bounds, curvature_bound
   use anm_testing, only: unittest_type, new_unittest, check
   implicit none
   private
   public :: collect_slicing

contains

   !> Tests of this suite.
   subroutine collect_slicing(tests)
      type(unittest_type), allocatable, intent(out) :: tests(:)
      tests = [ &
              new_unittest("plane: bad axes and pixel size are errors", test_plane_errors), &
              new_unittest("plane: pixel centres", test_pixel_center), &
              new_unittest("sphere section area across a periodic face", test_sphere_area), &
              new_unittest("shell layer of a sphere: area and particle wins", test_sphere_shell), &
              new_unittest("stack: fused radii equal each form's own radius", test_stack_radii), &
              new_unittest("stack: direction table bounds hold everywhere", test_stack_table), &
              new_unittest("stack: curvature bound of Y_n^m is n^2 max|Y|", test_curvature_bound)]
   end subroutine collect_slicing

   subroutine sphere(sh, r)
      type(sh_expansion_type), intent(out) :: sh
      real(wp), intent(in) :: r
      complex(wp) :: c(0:0, 0:0)
      c(0, 0) = cmplx(r * sqrt(4.0_wp * pi), 0.0_wp, wp)
      call new_sh_expansion(sh, c, 0)
   end subroutine sphere

   subroutine test_plane_errors(error)
      type(error_type), allocatable, intent(out) :: error
      type(slice_plane_type) :: plane
      type(error_type), allocatable :: e
      call new_slice_plane(plane, [0.0_wp, 0.0_wp, 0.0_wp], [1.0_wp, 0.0_wp, 0.0_wp], [0.5_wp, 0.5_wp, 0.0_wp], &
                           [1.0_wp, 1.0_wp], 0.1_wp, e)
      call check(error, allocated(e), "non-orthonormal axes rejected")
      if (allocated(error)) return
      call new_axis_plane(plane, 3, 1.0_wp, [1.0_wp, 1.0_wp], -0.1_wp, e)
      call check(error, allocated(e), "negative pixel rejected")
      if (allocated(error)) return
      call new_axis_plane(plane, 4, 1.0_wp, [1.0_wp, 1.0_wp], 0.1_wp, e)
      call check(error, allocated(e), "axis 4 rejected")
   end subroutine test_plane_errors

   subroutine test_pixel_center(error)
      type(error_type), allocatable, intent(out) :: error
      type(slice_plane_type) :: plane
      real(wp) :: x(3)
      call new_axis_plane(plane, 1, 2.0_wp, [4.0_wp, 3.0_wp], 0.5_wp, error)
      if (allocated(error)) return
      call check(error, plane%nu == 8 .and. plane%nv == 6, "pixel counts")
      if (allocated(error)) return
      x = pixel_center(plane, 2, 3)
      call check(error, maxval(abs(x - [2.0_wp, 0.75_wp, 1.25_wp])) < 1.0e-14_wp, "centre of pixel (2, 3)")
   end subroutine test_pixel_center

   subroutine test_sphere_area(error)
      type(error_type), allocatable, intent(out) :: error
      type(sh_expansion_type) :: sh
      type(slice_form_type) :: forms(1)
      type(slice_plane_type) :: planes(1)
      type(slice_stats_type) :: st
      integer, allocatable :: part(:, :, :), lay(:, :, :), own(:, :, :)
      integer :: shell_form(0, 1)
      real(wp) :: rot(3, 3, 1), area, pix
      call sphere(sh, 1.0_wp)
      call new_slice_form(forms(1), sh, error)
      if (allocated(error)) return
      pix = 0.01_wp
      call new_axis_plane(planes(1), 3, 2.5_wp, [4.0_wp, 4.0_wp], pix, error)
      if (allocated(error)) return
      allocate (part(400, 400, 1), lay(400, 400, 1), own(400, 400, 1))
      rot = 0.0_wp
      rot(1, 1, 1) = 1.0_wp
      rot(2, 2, 1) = 1.0_wp
      rot(3, 3, 1) = 1.0_wp
      ! centre 0.2 mm from the x = 0 face, 0.5 mm off the plane: section radius sqrt(0.75)
      call slice_labels(planes, forms, [1], shell_form, reshape([0.2_wp, 2.0_wp, 2.0_wp], [3, 1]), rot, [1.0_wp], &
                        [4.0_wp, 4.0_wp, 4.0_wp], .true., part, lay, own, st, error)
      if (allocated(error)) return
      area = count(part == 1) * pix**2
      call check(error, area, 0.75_wp * pi, "section area", rel=2.0e-3_wp)
      if (allocated(error)) return
      call check(error, count(part(381:400, :, 1) == 1) > 0, "periodic image at the x = 4 mm side")
   end subroutine test_sphere_area

   subroutine test_sphere_shell(error)
      type(error_type), allocatable, intent(out) :: error
      type(sh_expansion_type) :: sh(1)
      type(sh_expansion_type), allocatable :: outers(:, :)
      type(slice_form_type) :: forms(3)
      type(slice_plane_type) :: planes(1)
      type(slice_stats_type) :: st
      integer, allocatable :: part(:, :, :), lay(:, :, :), own(:, :, :)
      real(wp) :: rot(3, 3, 1), pix, a1, a2
      call sphere(sh(1), 1.0_wp)
      call build_shell_forms(sh, [1], reshape([0.1_wp, 0.3_wp], [2, 1]), outers, error)
      if (allocated(error)) return
      call new_slice_form(forms(1), sh(1), error)
      if (allocated(error)) return
      call new_slice_form(forms(2), outers(1, 1), error)
      if (allocated(error)) return
      call new_slice_form(forms(3), outers(2, 1), error)
      if (allocated(error)) return
      pix = 0.01_wp
      call new_axis_plane(planes(1), 3, 2.0_wp, [4.0_wp, 4.0_wp], pix, error)
      if (allocated(error)) return
      allocate (part(400, 400, 1), lay(400, 400, 1), own(400, 400, 1))
      rot = 0.0_wp
      rot(1, 1, 1) = 1.0_wp
      rot(2, 2, 1) = 1.0_wp
      rot(3, 3, 1) = 1.0_wp
      call slice_labels(planes, forms, [1], reshape([2, 3], [2, 1]), reshape([2.0_wp, 2.0_wp, 2.0_wp], [3, 1]), rot, &
                        [1.0_wp], [4.0_wp, 4.0_wp, 4.0_wp], .false., part, lay, own, st, error)
      if (allocated(error)) return
      a1 = count(lay == 1) * pix**2
      a2 = count(lay == 2) * pix**2
      call check(error, a1, pi * (1.1_wp**2 - 1.0_wp), "layer area", rel=1.0e-2_wp)
      if (allocated(error)) return
      call check(error, a2, pi * (1.3_wp**2 - 1.1_wp**2), "layer area", rel=1.0e-2_wp)
      if (allocated(error)) return
      call check(error, all(lay == 0 .or. part == 0), "no layer on particle pixels")
   end subroutine test_sphere_shell

   !> A rough random real expansion of degree nmax and mean radius r0 (coefficients ~ amp / n).
   subroutine rough(nmax, seed, r0, amp, shape)
      integer, intent(in) :: nmax
      integer(i8), intent(in) :: seed
      real(wp), intent(in) :: r0, amp
      type(sh_expansion_type), intent(out) :: shape
      type(rng_type) :: rng
      real(wp) :: a(0:nmax, 0:nmax), b(0:nmax, 0:nmax)
      integer :: n, m
      call new_rng(rng, seed, 5_i8)
      a = 0.0_wp
      b = 0.0_wp
      do n = 1, nmax
         do m = 0, n
            a(n, m) = amp * rng%normal() / n
            if (m > 0) b(n, m) = amp * rng%normal() / n
         end do
      end do
      a(0, 0) = r0 * 2.0_wp * sqrt(pi)
      call new_sh_expansion_real(shape, a, b)
   end subroutine rough

   !> Random unit directions, with the poles and the phi = 0 seam included.
   subroutine directions(n, seed, u)
      integer, intent(in) :: n
      integer(i8), intent(in) :: seed
      real(wp), allocatable, intent(out) :: u(:, :)
      type(rng_type) :: rng
      integer :: k
      call new_rng(rng, seed, 1_i8)
      allocate (u(3, n))
      do k = 1, n
         u(:, k) = [rng%normal(), rng%normal(), rng%normal()]
      end do
      u(:, 1) = [0.0_wp, 0.0_wp, 1.0_wp]
      u(:, 2) = [0.0_wp, 0.0_wp, -1.0_wp]
      u(:, 3) = [1.0_wp, 0.0_wp, 1.0e-9_wp]
      u(:, 4) = [1.0_wp, -1.0e-12_wp, 0.3_wp]
      do k = 1, n
         u(:, k) = u(:, k) / norm2(u(:, k))
      end do
   end subroutine directions

   subroutine test_stack_radii(error)
      type(error_type), allocatable, intent(out) :: error
      type(sh_expansion_type) :: forms(5)
      type(slice_stack_type) :: stack
      real(wp), allocatable :: u(:, :)
      real(wp) :: r(8), worst
      integer :: k, j
      integer, parameter :: orders(5) = [3, 17, 0, 28, 9]
      do j = 1, 5
         call rough(orders(j), int(j, i8), 1.0_wp + 0.1_wp * j, 0.05_wp, forms(j))
      end do
      call new_slice_stack(stack, forms)
      call check(error, stack%nform == 5 .and. stack%npad == 8 .and. stack%nmax == 28, "stack sizes")
      if (allocated(error)) return
      call directions(500, 3_i8, u)
      worst = 0.0_wp
      do k = 1, size(u, 2)
         call stack_radii(stack, 2.5_wp * u(:, k), r)
         do j = 1, 5
            worst = max(worst, abs(r(j) - forms(j)%radius_dir(u(:, k))))
         end do
      end do
      call check(error, worst < 1.0e-13_wp, "largest difference to radius_dir")
   end subroutine test_stack_radii

   subroutine test_stack_table(error)
      type(error_type), allocatable, intent(out) :: error
      type(sh_expansion_type) :: particle, layers(2)
      type(slice_stack_type) :: stack
      real(wp), allocatable :: u(:, :)
      real(wp) :: r(4), rp, lo, hp, hi, worst, gap(2)
      integer :: k, it
      integer, parameter :: ntheta(2) = [8, 128]
      call rough(14, 11_i8, 1.0_wp, 0.08_wp, particle)
      call rough(24, 12_i8, 1.1_wp, 0.08_wp, layers(1))
      call rough(20, 13_i8, 1.2_wp, 0.08_wp, layers(2))
      call directions(20000, 4_i8, u)
      do it = 1, 2
         call new_slice_stack(stack, layers)
         call build_stack_table(stack, particle, layers, ntheta(it))
         worst = huge(1.0_wp)
         gap(it) = 0.0_wp
         do k = 1, size(u, 2)
            call stack_radii(stack, u(:, k), r)
            rp = particle%radius_dir(u(:, k))
            call stack_table_bounds(stack, u(:, k), lo, hp, hi)
            worst = min(worst, rp - lo, hp - rp, hi - max(rp, r(1), r(2)))
            gap(it) = gap(it) + (hi - max(rp, r(1), r(2))) / size(u, 2)
         end do
         call check(error, worst >= 0.0_wp, "table bounds violated at ntheta = "//to_string(ntheta(it)))
         if (allocated(error)) return
      end do
      ! and useful: the mean excess of the upper bound falls with the cell size (about linearly,
      ! the corners' spread; the curvature term falls quadratically)
      call check(error, gap(2) < 0.1_wp * gap(1) .and. gap(2) < 0.05_wp, "mean excess of the upper bound: "// &
                 to_string(gap(1))//" (8 intervals), "//to_string(gap(2))//" (128)")
   end subroutine test_stack_table

   subroutine test_curvature_bound(error)
      type(error_type), allocatable, intent(out) :: error
      type(sh_expansion_type) :: sh
      real(wp) :: a(0:6, 0:6), b(0:6, 0:6)
      ! a single degree-6 harmonic: H = 36 ||c_6|| sqrt(13 / (4 pi)); for A_60 = 1, ||c_6|| = 1
      a = 0.0_wp
      b = 0.0_wp
      a(6, 0) = 1.0_wp
      call new_sh_expansion_real(sh, a, b)
      call check(error, curvature_bound(sh), 36.0_wp * sqrt(13.0_wp / (4.0_wp * pi)), "H of Pbar_6^0")
      if (allocated(error)) return
      ! a sine term counts with weight 1/2 in ||c_n||^2 (sqrt(2) Pbar sin(m phi) is orthonormal)
      a(6, 0) = 0.0_wp
      b(6, 3) = 2.0_wp
      call new_sh_expansion_real(sh, a, b)
      call check(error, curvature_bound(sh), 36.0_wp * sqrt(2.0_wp) * sqrt(13.0_wp / (4.0_wp * pi)), "H of a sine term")
   end subroutine test_curvature_bound

end module test_slicing
