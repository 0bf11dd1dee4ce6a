!> Tests of particle geometry and poses against outside truth: NIST's geometry table for every
!> MA111-7-coarse particle at the order NIST used, the thesis' extent scan against the refined
!> box, uniform random rotations by a chi-square test (with uniform Euler angles as the negative
!> control the test must reject), and body/world transforms.
module test_geometry
   use anm_core_kinds, only: wp, pi, two_pi, i8
   use anm_core_statistics, only: median
   use anm_core_error, only: error_type, fatal_error
   use anm_core_random, only: rng_type, new_rng
   use anm_core_strings, only: to_string
   use anm_sh_expansion, only: sh_expansion_type
   use anm_shapes_library, only: load_shape_file
   use anm_shapes_analytic, only: ellipsoid_shape
   use anm_geometry_properties, only: shape_geometry_type, compute_geometry
   use anm_geometry_radial_bound, only: radial_bound_type, radial_cell
   use anm_contact_body, only: contact_body_type, new_contact_body, radial_bound
   use anm_sh_expansion, only: sh_truncate
   use anm_geometry_rotation, only: random_rotation, quaternion_to_matrix, body_to_world, world_to_body, &
      & rotation_about_axis, scale_for_width, is_rotation
   use anm_testing, only: unittest_type, new_unittest, check, shapes_dir
   implicit none
   private
   public :: collect_geometry

contains

   !> Tests of this suite.
   subroutine collect_geometry(tests)
      type(unittest_type), allocatable, intent(out) :: tests(:)
      tests = [ &
              new_unittest("MA111-7-coarse geometry agrees with NIST's table", test_nist_table), &
              new_unittest("thesis extent scan lies inside the refined box and converges", test_extent_scan), &
              new_unittest("random rotations are uniform (chi-square)", test_rotation_uniform), &
              new_unittest("uniform Euler angles fail the same test", test_euler_not_uniform, should_fail=.true.), &
              new_unittest("random rotations are proper orthogonal", test_rotation_proper), &
              new_unittest("body-world transforms invert each other", test_transforms), &
              new_unittest("scaling to a target width", test_scale_width), &
              new_unittest("radial bounds hold and leave the dimensions bit for bit the same", test_radial_bound)]
   end subroutine collect_geometry

   !> Radius bounds per cube-map cell (radial_bound, from the contact body's leaf patches): an
   !> ellipsoid and real shapes at orders 14 and 6; at 50,000 random directions u, r(u) never
   !> exceeds its cell's bound, and the bounds are close (mean excess below 15 % of r); the
   !> dimensions computed with them (chord marches that skip points the bounds put outside) equal
   !> those computed without, bit for bit.
   subroutine test_radial_bound(error)
      type(error_type), allocatable, intent(out) :: error
      character(len=:), allocatable :: dir
      type(sh_expansion_type) :: shape
      type(contact_body_type) :: body
      type(radial_bound_type) :: rb
      type(shape_geometry_type) :: g0, g1
      type(rng_type) :: rng
      real(wp) :: u(3), r, excess, worst
      integer :: ic, k
      logical :: same
      call shapes_dir(dir, error)
      if (allocated(error)) return
      call new_rng(rng, 5_i8, 1_i8)
      do ic = 1, 4
         select case (ic)
         case (1)
            shape = ellipsoid_shape(2.0_wp, 1.2_wp, 0.7_wp, 12)
         case (2)
            call load_shape_file(dir//"/MA111-7-coarse/MA111-7-coarse-anm-00002.dat", shape, error)
            shape = sh_truncate(shape, 14)
         case (3)
            call load_shape_file(dir//"/MA111-7-coarse/MA111-7-coarse-anm-00009.dat", shape, error)
            shape = sh_truncate(shape, 14)
         case (4)
            call load_shape_file(dir//"/MA107-6-fine/MA107-6-fine-anm-00002.dat", shape, error)
            shape = sh_truncate(shape, 6)
         end select
         if (allocated(error)) return
         call new_contact_body(body, shape, error, table=.false.)
         if (allocated(error)) return
         rb = radial_bound(body, 16)
         excess = 0.0_wp
         worst = 0.0_wp
         do k = 1, 50000
            u = random_unit(rng)
            r = shape%radius_dir(u)
            worst = max(worst, r / rb%rmax(radial_cell(rb%n, u)))
            excess = excess + (rb%rmax(radial_cell(rb%n, u)) - r) / r
         end do
         excess = excess / 50000
         write (*, '(a,i0,a,f8.5,a,f7.4)') "        shape ", ic, ": largest r / bound ", worst, &
            ", mean excess of the bound ", excess
         call check(error, worst <= 1.0_wp, "shape "//to_string(ic)//": r exceeds its cell's bound")
         if (allocated(error)) return
         call check(error, excess < 0.15_wp, "shape "//to_string(ic)//": bounds loose")
         if (allocated(error)) return
         call compute_geometry(shape, g0)
         call compute_geometry(shape, g1, bound=rb)
         same = g0%length == g1%length .and. g0%width == g1%width .and. g0%thickness == g1%thickness &
                .and. all(g0%dir_length == g1%dir_length) .and. all(g0%dir_width == g1%dir_width) &
                .and. all(g0%dir_thickness == g1%dir_thickness) .and. g0%volume == g1%volume
         call check(error, same, "shape "//to_string(ic)//": dimensions differ with the bounds")
         if (allocated(error)) return
      end do
   contains
      function random_unit(rng) result(v)
         type(rng_type), intent(inout) :: rng
         real(wp) :: v(3), z, ph
         z = 2.0_wp * rng%uniform() - 1.0_wp
         ph = two_pi * rng%uniform()
         v = [sqrt(max(0.0_wp, 1.0_wp - z * z)) * cos(ph), sqrt(max(0.0_wp, 1.0_wp - z * z)) * sin(ph), z]
      end function random_unit
   end subroutine test_radial_bound

   subroutine test_nist_table(error)
      type(error_type), allocatable, intent(out) :: error
      character(len=:), allocatable :: dir, folder
      character(len=64), allocatable :: names(:)
      real(wp), allocatable :: tab(:, :), ev(:, :)
      real(wp) :: worst(6), medw, medt
      character(len=64) :: worst_name(6)
      type(shape_geometry_type), allocatable :: g(:)
      type(sh_expansion_type), allocatable :: shapes(:)
      logical, allocatable :: have(:)
      integer :: nrow, k, i, j, nhave
      character(len=*), parameter :: label(6) = [character(len=10) :: "volume", "area", "extents", &
                                                                         "length", "width", "thickness"]

      call shapes_dir(dir, error)
      if (allocated(error)) return
      folder = dir//"/MA111-7-coarse"
      call read_geom_table(folder//"/MA111-7-coarse-geom.orig.dat", names, tab, error)
      if (allocated(error)) return
      nrow = size(names)
      allocate (have(nrow), shapes(nrow), g(nrow))
      do k = 1, nrow
         inquire (file=folder//"/"//trim(names(k)), exist=have(k))
         if (have(k)) then
            call load_shape_file(folder//"/"//trim(names(k)), shapes(k), error)
            if (allocated(error)) return
         end if
      end do
      nhave = count(have)
      call check(error, nhave >= 24, "expected the 24 MA111-7-coarse particles, found "//to_string(nhave))
      if (allocated(error)) return
      !$omp parallel do default(shared) private(k) schedule(dynamic)
      do k = 1, nrow
         ! column 12 of the numeric table is Nnn, the order NIST used
         if (have(k)) call compute_geometry(shapes(k), g(k), nused=nint(tab(12, k)))
      end do
      !$omp end parallel do
      ! relative errors: V, S, max extent error / L, L, W, T
      allocate (ev(6, nhave))
      j = 0
      do k = 1, nrow
         if (.not. have(k)) cycle
         j = j + 1
         ev(1, j) = g(k)%volume / tab(7, k) - 1.0_wp
         ev(2, j) = g(k)%area / tab(8, k) - 1.0_wp
         ev(3, j) = max(maxval(abs(g(k)%extent_lo - tab([1, 3, 5], k))), &
                        maxval(abs(g(k)%extent_hi - tab([2, 4, 6], k)))) / tab(14, k)
         ev(4, j) = g(k)%length / tab(14, k) - 1.0_wp
         ev(5, j) = g(k)%width / tab(15, k) - 1.0_wp
         ev(6, j) = g(k)%thickness / tab(16, k) - 1.0_wp
      end do
      do i = 1, 6
         worst(i) = maxval(abs(ev(i, :)))
         j = 0
         do k = 1, nrow
            if (.not. have(k)) cycle
            j = j + 1
            if (abs(ev(i, j)) == worst(i)) worst_name(i) = names(k)
         end do
         print '(a,a10,a,f7.3,a,a)', "        worst ", label(i), ": ", 100 * worst(i), " %  ", trim(worst_name(i))
      end do
      medw = median(abs(ev(5, :)))
      medt = median(abs(ev(6, :)))
      print '(a,f6.2,a,f6.2,a)', "        median |error| width ", 100 * medw, " %, thickness ", 100 * medt, " %"
      call check(error, worst(1) <= 1.0e-3_wp, "volume within 0.1 %")
      if (allocated(error)) return
      call check(error, worst(2) <= 5.0e-3_wp, "area within 0.5 %")
      if (allocated(error)) return
      call check(error, worst(3) <= 5.0e-3_wp, "extents within 0.5 % of L")
      if (allocated(error)) return
      call check(error, worst(4) <= 1.5e-2_wp, "length within 1.5 %")
      if (allocated(error)) return
      call check(error, medw <= 3.0e-2_wp .and. worst(5) <= 0.12_wp, "width: median <= 3 %, max <= 12 %")
      if (allocated(error)) return
      call check(error, medt <= 3.0e-2_wp .and. worst(6) <= 0.12_wp, "thickness: median <= 3 %, max <= 12 %")
   end subroutine test_nist_table

   !> Read a NIST geometry table: names and the 18 numeric columns (column 1 = xlow, ... 12 = Nnn,
   !> 14 = length, 15 = width, 16 = thick).
   subroutine read_geom_table(path, names, tab, error)
      character(len=*), intent(in) :: path
      character(len=64), allocatable, intent(out) :: names(:)
      real(wp), allocatable, intent(out) :: tab(:, :)
      type(error_type), allocatable, intent(out) :: error
      character(len=1024) :: line
      integer :: unit, stat, n, k
      open (newunit=unit, file=path, status="old", action="read", iostat=stat)
      if (stat /= 0) then
         call fatal_error(error, path//": cannot open")
         return
      end if
      n = 0
      read (unit, '(a)') line
      do
         read (unit, '(a)', iostat=stat) line
         if (stat /= 0) exit
         if (len_trim(line) > 0) n = n + 1
      end do
      rewind (unit)
      read (unit, '(a)') line
      allocate (names(n), tab(18, n))
      do k = 1, n
         read (unit, '(a)') line
         read (line, *, iostat=stat) names(k), tab(:, k)
         if (stat /= 0) then
            call fatal_error(error, path//": cannot parse row "//to_string(k + 1))
            close (unit)
            return
         end if
      end do
      close (unit)
   end subroutine read_geom_table

   subroutine test_extent_scan(error)
      type(error_type), allocatable, intent(out) :: error
      type(shape_geometry_type) :: ref, g40, g200
      type(sh_expansion_type) :: s
      real(wp) :: box_ref, box40, box200
      s = ellipsoid_shape(3.0_wp, 2.0_wp, 1.0_wp, 20)
      call compute_geometry(s, ref)
      call compute_geometry(s, g40, next=40)
      call compute_geometry(s, g200, next=200)
      box_ref = product(ref%extent_hi - ref%extent_lo)
      box40 = product(g40%extent_hi - g40%extent_lo)
      box200 = product(g200%extent_hi - g200%extent_lo)
      print '(a,3f10.5)', "        box volume ref, N_ext=40, N_ext=200: ", box_ref, box40, box200
      ! the scan samples the surface: it cannot exceed the refined box, and it converges to it
      call check(error, box40 <= box_ref * (1 + 1.0e-12_wp) .and. box200 <= box_ref * (1 + 1.0e-12_wp), "inside")
      if (allocated(error)) return
      call check(error, abs(box200 - box_ref) <= abs(box40 - box_ref), "converges")
      if (allocated(error)) return
      ! exact box of the ellipsoid is 6 x 4 x 2 = 48 (up to the order-20 truncation)
      call check(error, box_ref, 48.0_wp, "ellipsoid box", rel=1.0e-3_wp)
   end subroutine test_extent_scan

   !> Chi-square statistic of n unit vectors over 100 equal-area cells (10 bands in z x 10 sectors).
   function chi_square(v) result(chi2)
      real(wp), intent(in) :: v(:, :)
      real(wp) :: chi2, expct, ph
      integer :: counts(10, 10), k, iz, ip
      counts = 0
      do k = 1, size(v, 2)
         iz = min(10, 1 + int((v(3, k) + 1.0_wp) * 5.0_wp))
         ph = atan2(v(2, k), v(1, k)) + pi
         ip = min(10, 1 + int(ph / two_pi * 10.0_wp))
         counts(iz, ip) = counts(iz, ip) + 1
      end do
      expct = size(v, 2) / 100.0_wp
      chi2 = sum((counts - expct)**2 / expct)
   end function chi_square

   subroutine test_rotation_uniform(error)
      type(error_type), allocatable, intent(out) :: error
      ! chi-square with 99 degrees of freedom: P(chi2 > 148.2) = 0.001; fixed seed
      real(wp), parameter :: threshold = 148.2_wp
      type(rng_type) :: rng
      real(wp) :: v(3, 20000), chi2, rot(3, 3)
      integer :: k
      call new_rng(rng, 12345_i8, 0_i8)
      do k = 1, size(v, 2)
         rot = random_rotation(rng)
         v(:, k) = rot(:, 3)
      end do
      chi2 = chi_square(v)
      print '(a,f8.2,a,f6.1,a)', "        chi-square of rotated z axes: ", chi2, " (threshold ", threshold, ")"
      call check(error, chi2 < threshold, "rotated z axis not uniform: chi2 = "//to_string(chi2))
      if (allocated(error)) return
      ! the rotated x axis as well
      do k = 1, size(v, 2)
         rot = random_rotation(rng)
         v(:, k) = rot(:, 1)
      end do
      chi2 = chi_square(v)
      call check(error, chi2 < threshold, "rotated x axis not uniform: chi2 = "//to_string(chi2))
   end subroutine test_rotation_uniform

   subroutine test_euler_not_uniform(error)
      type(error_type), allocatable, intent(out) :: error
      real(wp), parameter :: threshold = 148.2_wp
      type(rng_type) :: rng
      real(wp) :: v(3, 20000), chi2, rot(3, 3), a, b, c
      integer :: k
      call new_rng(rng, 12345_i8, 0_i8)
      do k = 1, size(v, 2)
         a = two_pi * rng%uniform()
         b = pi * rng%uniform()
         c = two_pi * rng%uniform()
         rot = matmul(rotation_about_axis([0.0_wp, 0.0_wp, 1.0_wp], a), &
                      matmul(rotation_about_axis([0.0_wp, 1.0_wp, 0.0_wp], b), &
                             rotation_about_axis([0.0_wp, 0.0_wp, 1.0_wp], c)))
         v(:, k) = rot(:, 3)
      end do
      chi2 = chi_square(v)
      print '(a,f9.1)', "        chi-square of uniform Euler angles (must fail): ", chi2
      call check(error, chi2 < threshold, "Euler angles rejected, chi2 = "//to_string(chi2))
   end subroutine test_euler_not_uniform

   subroutine test_rotation_proper(error)
      type(error_type), allocatable, intent(out) :: error
      type(rng_type) :: rng
      integer :: k
      call new_rng(rng, 7_i8, 1_i8)
      do k = 1, 1000
         call check(error, is_rotation(random_rotation(rng), 1.0e-13_wp), "not a rotation")
         if (allocated(error)) return
      end do
   end subroutine test_rotation_proper

   subroutine test_transforms(error)
      type(error_type), allocatable, intent(out) :: error
      type(rng_type) :: rng
      real(wp) :: rot(3, 3), c(3), y(3), x(3)
      integer :: k
      call new_rng(rng, 8_i8, 1_i8)
      do k = 1, 100
         rot = random_rotation(rng)
         c = [rng%uniform(), rng%uniform(), rng%uniform()] * 10.0_wp
         y = [rng%normal(), rng%normal(), rng%normal()]
         x = body_to_world(rot, c, 2.5_wp, y)
         call check(error, norm2(world_to_body(rot, c, 2.5_wp, x) - y), 0.0_wp, "round trip", thr=1.0e-13_wp)
         if (allocated(error)) return
         call check(error, norm2(x - c), 2.5_wp * norm2(y), "distance scales", rel=1.0e-13_wp)
         if (allocated(error)) return
      end do
      ! a quarter turn about z maps body x to world y
      rot = rotation_about_axis([0.0_wp, 0.0_wp, 1.0_wp], 0.5_wp * pi)
      x = body_to_world(rot, [0.0_wp, 0.0_wp, 0.0_wp], 1.0_wp, [1.0_wp, 0.0_wp, 0.0_wp])
      call check(error, norm2(x - [0.0_wp, 1.0_wp, 0.0_wp]), 0.0_wp, "quarter turn", thr=1.0e-15_wp)
   end subroutine test_transforms

   subroutine test_scale_width(error)
      type(error_type), allocatable, intent(out) :: error
      type(shape_geometry_type) :: g
      call compute_geometry(ellipsoid_shape(3.0_wp, 2.0_wp, 1.0_wp, 16), g)
      ! width of the 3:2:1 ellipsoid is 4; scaling to 10 mm gives 2.5 mm per unit
      call check(error, scale_for_width(g%width, 10.0_wp) * g%width, 10.0_wp, "scaled width", rel=1.0e-14_wp)
      if (allocated(error)) return
      call check(error, scale_for_width(g%width, 10.0_wp), 2.5_wp, "scale", rel=2.0e-3_wp)
   end subroutine test_scale_width
end module test_geometry
