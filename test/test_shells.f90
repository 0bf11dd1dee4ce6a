!> Tests of uniform-thickness shells against outside truth: the sphere (R + t exactly), Steiner's
!> formula for convex ellipsoids (V, S and the mean-curvature integral M computed here by
!> quadrature of the analytic ellipsoid), brute-force distances for real CT shapes, one shell of
!> 5t against five nested shells of t (the thesis' question, Minkowski: B_t + ... + B_t = B_5t),
!> the thin-shell limit S t, every MA111-7-coarse particle at 0.1, 2, 5 and 10 % of its length,
!> and bad input.
module test_shells
   use, intrinsic :: iso_fortran_env, only: output_unit
   use anm_core_kinds, only: wp, pi, two_pi, i8
   use anm_core_error, only: error_type, fatal_error
   use anm_core_random, only: rng_type, new_rng
   use anm_core_strings, only: to_string
   use anm_sh_expansion, only: sh_expansion_type, sh_truncate
   use anm_sh_grid, only: sh_grid_type, new_sh_grid, sh_grid_normals
   use anm_sh_quadrature, only: gauss_legendre
   use anm_shapes_library, only: shape_set_type, load_shapes
   use anm_shapes_analytic, only: sphere_shape, ellipsoid_shape
   use anm_geometry_properties, only: shape_geometry_type, compute_geometry
   use anm_shells_surface, only: shell_surface_type, new_shell_surface
   use anm_shells_offset, only: offset_radius, offset_grid, offset_counts_type
   use anm_shapes_synthetic, only: synthetic_params_type, make_synthetic_shape
   use anm_shells_build, only: shell_report_type, build_shell, build_layers
   use anm_shells_thickness, only: thickness_spec_type, thickness_unit, thickness_in_shape_units
   use anm_testing, only: unittest_type, new_unittest, check, shapes_dir
   implicit none
   private
   public :: collect_shells

   !> Degree at which the real shapes are used in these tests.
   integer, parameter :: test_degree = 14
   !> Polar nodes of the direction grid in the real-shape tests (nphi = 2 ntheta).
   integer, parameter :: test_ntheta = 48
   !> Documented bound (docs/shells.md) on the depth of the lifted fitted surface inside R_t at
   !> the grid nodes, relative to t.
   real(wp), parameter :: node_inside_bound = 0.02_wp
   !> Documented bound on that depth at arbitrary directions (between the nodes), relative to t.
   real(wp), parameter :: inside_bound = 0.1_wp

contains

   !> Tests of this suite.
   subroutine collect_shells(tests)
      type(unittest_type), allocatable, intent(out) :: tests(:)
      tests = [ &
              new_unittest("sphere: shell radius is R + t", test_sphere), &
              new_unittest("ellipsoids: shell volume follows Steiner's formula", test_steiner), &
              new_unittest("real shapes: shell points are at distance t (brute force)", test_brute_force), &
              new_unittest("real shapes: one shell of 5t equals five nested shells of t", test_five_layers), &
              new_unittest("real shapes: thin shell volume is S t", test_thin_shell), &
              new_unittest("MA111-7-coarse: shells of 0.1, 2, 5 and 10 % of L", test_all_coarse), &
              new_unittest("grid R_t agrees with the distance-validated reference", test_grid_reference), &
              new_unittest("synthetic shapes: shells of 0.5, 2, 5 and 10 % of L", test_synthetic), &
              new_unittest("fitted surface lies inside R_t by at most its bound", test_fit_bound), &
              new_unittest("layers: volumes add up to the outermost shell", test_layers), &
              new_unittest("thickness in mm and as a fraction of length", test_thickness_spec), &
              new_unittest("zero thickness is refused", test_zero_thickness, should_fail=.true.), &
              new_unittest("negative thickness error names particle and thickness", test_negative_message)]
   end subroutine collect_shells

   subroutine test_sphere(error)
      type(error_type), allocatable, intent(out) :: error
      type(sh_expansion_type) :: outer
      type(shell_report_type) :: rep
      type(rng_type) :: rng
      real(wp), parameter :: rad = 1.7_wp, ts(3) = [0.001_wp, 0.1_wp, 0.5_wp] * 2.0_wp * rad
      real(wp) :: u(3), worst
      integer :: k, i

      call new_rng(rng, 11_i8, 1_i8)
      do k = 1, size(ts)
         call build_shell(sphere_shape(rad), ts(k), outer, rep, error, label="sphere", ntheta=24)
         if (allocated(error)) return
         worst = 0.0_wp
         do i = 1, 200
            u = [rng%normal(), rng%normal(), rng%normal()]
            worst = max(worst, abs(outer%radius_dir(u) - (rad + ts(k))))
         end do
         call check(error, worst, 0.0_wp, "sphere t = "//to_string(ts(k)), thr=1.0e-10_wp * (rad + ts(k)))
         if (allocated(error)) return
         call check(error, rep%fallback, 0, "sphere fallbacks")
         if (allocated(error)) return
      end do
   end subroutine test_sphere

   subroutine test_steiner(error)
      type(error_type), allocatable, intent(out) :: error
      real(wp), parameter :: axes(3, 2) = reshape([1.0_wp, 0.8_wp, 0.6_wp, 1.2_wp, 1.0_wp, 0.7_wp], [3, 2])
      real(wp), parameter :: fracs(3) = [0.01_wp, 0.1_wp, 0.2_wp]
      type(sh_expansion_type) :: outer
      type(shell_report_type) :: rep
      real(wp) :: vol, area, mcurv, t, steiner
      integer :: e, k

      do e = 1, size(axes, 2)
         call ellipsoid_integrals(axes(1, e), axes(2, e), axes(3, e), area, mcurv)
         vol = 4.0_wp / 3.0_wp * pi * product(axes(:, e))
         do k = 1, size(fracs)
            t = fracs(k) * minval(axes(:, e))
            call build_shell(ellipsoid_shape(axes(1, e), axes(2, e), axes(3, e), 24), t, outer, rep, error, &
                             label="ellipsoid", ntheta=64)
            if (allocated(error)) return
            steiner = area * t + mcurv * t**2 + 4.0_wp / 3.0_wp * pi * t**3
            write (output_unit, '(4x,a,3f5.2,a,f5.2,a,es10.2,a,i0,a,i0)') "ellipsoid", axes(:, e), " t/c", fracs(k), &
               " shell volume / Steiner - 1 =", rep%shell_volume / steiner - 1.0_wp, ", fallbacks ", rep%fallback, &
               ", order ", rep%order
            call check(error, rep%particle_volume, vol, "ellipsoid volume", rel=1.0e-9_wp)
            if (allocated(error)) return
            call check(error, rep%shell_volume, steiner, "Steiner, t/c = "//to_string(fracs(k)), rel=1.0e-4_wp)
            if (allocated(error)) return
         end do
      end do
   end subroutine test_steiner

   !> Area S and integral of mean curvature M = int (k1 + k2)/2 dA of the ellipsoid with semi-axes
   !> (a, b, c), by Gauss-Legendre in cos(u) x trapezoid in v of x = (a sin u cos v, b sin u sin v,
   !> c cos u) with the fundamental forms written out analytically (independent of the SH code).
   subroutine ellipsoid_integrals(a, b, c, area, mcurv)
      real(wp), intent(in) :: a, b, c
      real(wp), intent(out) :: area, mcurv
      integer, parameter :: nu = 200, nv = 400
      real(wp), allocatable :: z(:), w(:)
      real(wp) :: su, cu, sv, cv, xu(3), xv(3), xuu(3), xuv(3), xvv(3), nrm(3), jac, ee, ff, gg, ll, mm, nn, h, dv
      integer :: i, j

      call gauss_legendre(nu, z, w)
      dv = two_pi / nv
      area = 0.0_wp
      mcurv = 0.0_wp
      do i = 1, nu
         cu = z(i)
         su = sqrt(1.0_wp - cu * cu)
         do j = 1, nv
            cv = cos((j - 1) * dv)
            sv = sin((j - 1) * dv)
            xu = [a * cu * cv, b * cu * sv, -c * su]
            xv = [-a * su * sv, b * su * cv, 0.0_wp]
            xuu = [-a * su * cv, -b * su * sv, -c * cu]
            xuv = [-a * cu * sv, b * cu * cv, 0.0_wp]
            xvv = [-a * su * cv, -b * su * sv, 0.0_wp]
            nrm = [xu(2) * xv(3) - xu(3) * xv(2), xu(3) * xv(1) - xu(1) * xv(3), xu(1) * xv(2) - xu(2) * xv(1)]
            jac = norm2(nrm)
            nrm = nrm / jac
            ee = dot_product(xu, xu)
            ff = dot_product(xu, xv)
            gg = dot_product(xv, xv)
            ll = dot_product(xuu, nrm)
            mm = dot_product(xuv, nrm)
            nn = dot_product(xvv, nrm)
            ! outward normal: the sign of H is fixed by requiring H > 0 (convex body)
            h = abs(ee * nn - 2.0_wp * ff * mm + gg * ll) / (2.0_wp * (ee * gg - ff * ff))
            ! du = dz / sin u
            area = area + w(i) * dv * jac / su
            mcurv = mcurv + w(i) * dv * h * jac / su
         end do
      end do
   end subroutine ellipsoid_integrals

   !> First `count` particles of MA111-7-coarse truncated at test_degree, with their geometry.
   subroutine coarse_shapes(count, shapes, names, geom, error)
      integer, intent(in) :: count
      type(sh_expansion_type), allocatable, intent(out) :: shapes(:)
      character(len=64), allocatable, intent(out) :: names(:)
      type(shape_geometry_type), allocatable, intent(out) :: geom(:)
      type(error_type), allocatable, intent(out) :: error
      character(len=:), allocatable :: dir
      type(shape_set_type) :: set
      integer :: k, n

      call shapes_dir(dir, error)
      if (allocated(error)) return
      call load_shapes(dir//"/MA111-7-coarse", set, error)
      if (allocated(error)) return
      n = min(count, size(set%shapes))
      allocate (shapes(n), names(n), geom(n))
      do k = 1, n
         shapes(k) = sh_truncate(set%shapes(k), test_degree)
         names(k) = set%names(k)%s
         call compute_geometry(shapes(k), geom(k))
      end do
   end subroutine coarse_shapes

   !> Distance from y to the surface of `shape` by brute force: the nearest of a dense sample,
   !> then three zooms of a 21 x 21 angular lattice around the best point.
   function brute_distance(shape, xs, y) result(d)
      type(sh_expansion_type), intent(in) :: shape
      real(wp), intent(in) :: xs(:, :, :), y(3)
      real(wp) :: d, best, th0, ph0, th, ph, step, dd, bt, bp
      integer :: i, j, k, loc(2), nt, np
      real(wp), allocatable :: dist(:, :)

      nt = size(xs, 2)
      np = size(xs, 3)
      allocate (dist(nt, np))
      do j = 1, np
         do i = 1, nt
            dist(i, j) = norm2(y - xs(:, i, j))
         end do
      end do
      loc = minloc(dist)
      best = dist(loc(1), loc(2))
      th0 = acos(xs(3, loc(1), loc(2)) / norm2(xs(:, loc(1), loc(2))))
      ph0 = atan2(xs(2, loc(1), loc(2)), xs(1, loc(1), loc(2)))
      step = 2.0_wp * pi / np
      do k = 1, 4
         bt = th0
         bp = ph0
         do j = -10, 10
            do i = -10, 10
               th = th0 + i * step / 10.0_wp * 2.0_wp
               ph = ph0 + j * step / 10.0_wp * 2.0_wp
               dd = norm2(y - shape%radius(th, ph) * [sin(th) * cos(ph), sin(th) * sin(ph), cos(th)])
               if (dd < best) then
                  best = dd
                  bt = th
                  bp = ph
               end if
            end do
         end do
         th0 = bt
         ph0 = bp
         step = step / 5.0_wp
      end do
      d = best
   end function brute_distance

   subroutine test_brute_force(error)
      type(error_type), allocatable, intent(out) :: error
      type(sh_expansion_type), allocatable :: shapes(:)
      character(len=64), allocatable :: names(:)
      type(shape_geometry_type), allocatable :: geom(:)
      type(shell_surface_type) :: surf
      type(sh_grid_type) :: dense
      type(sh_expansion_type) :: outer
      type(shell_report_type) :: rep
      type(rng_type) :: rng
      real(wp), allocatable :: xs(:, :, :), ns(:, :, :)
      real(wp), parameter :: fracs(3) = [0.002_wp, 0.02_wp, 0.1_wp]
      real(wp) :: t, u(3), th, ph, rt, d, worst, worst_fit, rms_fit
      integer :: k, f, i, nfb, npt
      logical :: fb

      call coarse_shapes(2, shapes, names, geom, error)
      if (allocated(error)) return
      dense = new_sh_grid(240, 480, test_degree)
      allocate (xs(3, 240, 480), ns(3, 240, 480))
      call new_rng(rng, 7_i8, 2_i8)
      npt = 25
      do k = 1, size(shapes)
         call sh_grid_normals(dense, shapes(k), xs, ns)
         call new_shell_surface(surf, shapes(k), test_ntheta, test_degree)
         do f = 1, size(fracs)
            t = fracs(f) * geom(k)%length
            call build_shell(shapes(k), t, outer, rep, error, label=trim(names(k)), ntheta=test_ntheta)
            if (allocated(error)) return
            worst = 0.0_wp
            worst_fit = 0.0_wp
            rms_fit = 0.0_wp
            nfb = 0
            do i = 1, npt
               u = [rng%normal(), rng%normal(), rng%normal()]
               u = u / norm2(u)
               th = acos(u(3))
               ph = atan2(u(2), u(1))
               call offset_radius(surf, th, ph, t, rt, fb)
               if (fb) nfb = nfb + 1
               d = brute_distance(shapes(k), xs, rt * u)
               worst = max(worst, abs(d - t) / t)
               d = brute_distance(shapes(k), xs, outer%radius_dir(u) * u)
               worst_fit = max(worst_fit, abs(d - t) / t)
               rms_fit = rms_fit + ((d - t) / t)**2
            end do
            rms_fit = sqrt(rms_fit / npt)
            write (output_unit, '(4x,a,a,f6.3,a,es9.2,a,es9.2,a,es9.2,a,i0,a,i0)') trim(names(k)), " t/L", fracs(f), &
               ": |d-t|/t R_t max", worst, ", fitted max", worst_fit, " rms", rms_fit, ", order ", rep%order, &
               ", fallback points ", nfb
            call check(error, worst, 0.0_wp, trim(names(k))//" t/L = "//to_string(fracs(f))//" R_t distance", &
                       thr=5.0e-3_wp)
            if (allocated(error)) return
            call check(error, rms_fit, 0.0_wp, trim(names(k))//" t/L = "//to_string(fracs(f))//" fitted rms", &
                       thr=0.05_wp)
            if (allocated(error)) return
         end do
      end do
   end subroutine test_brute_force

   !> Nested shells are built on the fitted (order 28) outer surface of the previous one; three
   !> particles (00002, 00003, 00004).
   subroutine test_five_layers(error)
      type(error_type), allocatable, intent(out) :: error
      type(sh_expansion_type), allocatable :: shapes(:)
      character(len=64), allocatable :: names(:)
      type(shape_geometry_type), allocatable :: geom(:)
      type(sh_expansion_type) :: inner, outer
      type(shell_report_type) :: rep, rep5
      real(wp) :: t, v0
      integer :: k, l

      call coarse_shapes(3, shapes, names, geom, error)
      if (allocated(error)) return
      do k = 1, size(shapes)
         t = 0.01_wp * geom(k)%length
         call build_shell(shapes(k), 5.0_wp * t, outer, rep5, error, label=trim(names(k)), ntheta=64, &
                          order=2 * test_degree, conservative=.false.)
         if (allocated(error)) return
         inner = shapes(k)
         do l = 1, 5
            call build_shell(inner, t, outer, rep, error, label=trim(names(k))//" nested "//to_string(l), &
                             ntheta=64, order=2 * test_degree, conservative=.false.)
            if (allocated(error)) return
            if (l == 1) v0 = rep%particle_volume
            inner = outer
         end do
         write (output_unit, '(4x,a,a,es10.2)') trim(names(k)), ": five nested shells of t / one shell of 5t - 1 =", &
            (rep%outer_volume - v0) / rep5%shell_volume - 1.0_wp
         call check(error, rep%outer_volume - v0, rep5%shell_volume, trim(names(k))//" 5 x t vs 5t", rel=1.0e-3_wp)
         if (allocated(error)) return
      end do
   end subroutine test_five_layers

   subroutine test_thin_shell(error)
      type(error_type), allocatable, intent(out) :: error
      type(sh_expansion_type), allocatable :: shapes(:)
      character(len=64), allocatable :: names(:)
      type(shape_geometry_type), allocatable :: geom(:)
      type(sh_expansion_type) :: outer
      type(shell_report_type) :: rep
      real(wp) :: t
      integer :: k

      call coarse_shapes(2, shapes, names, geom, error)
      if (allocated(error)) return
      do k = 1, size(shapes)
         t = 1.0e-4_wp * geom(k)%length
         call build_shell(shapes(k), t, outer, rep, error, label=trim(names(k)), ntheta=test_ntheta)
         if (allocated(error)) return
         write (output_unit, '(4x,a,a,es10.2)') trim(names(k)), ": thin shell volume / (S t) - 1 =", &
            rep%shell_volume / (geom(k)%area * t) - 1.0_wp
         call check(error, rep%shell_volume, geom(k)%area * t, trim(names(k))//" thin shell", rel=2.0e-2_wp)
         if (allocated(error)) return
      end do
   end subroutine test_thin_shell

   subroutine test_all_coarse(error)
      type(error_type), allocatable, intent(out) :: error
      type(sh_expansion_type), allocatable :: shapes(:)
      character(len=64), allocatable :: names(:)
      type(shape_geometry_type), allocatable :: geom(:)
      real(wp), parameter :: fracs(4) = [0.001_wp, 0.02_wp, 0.05_wp, 0.10_wp]
      type(shell_report_type), allocatable :: reps(:, :)
      character(len=512), allocatable :: msgs(:, :)
      type(error_type), allocatable :: err
      type(sh_expansion_type) :: outer
      integer :: k, f, nshape
      real(wp) :: worst

      call coarse_shapes(24, shapes, names, geom, error)
      if (allocated(error)) return
      nshape = size(shapes)
      call check(error, nshape, 24, "MA111-7-coarse particles")
      if (allocated(error)) return
      allocate (reps(size(fracs), nshape), msgs(size(fracs), nshape))
      msgs = ""
      !$omp parallel do default(none) shared(shapes, names, geom, reps, msgs, nshape) private(k, f, outer, err) &
      !$omp schedule(dynamic) collapse(2)
      do k = 1, nshape
         do f = 1, size(fracs)
            call build_shell(shapes(k), fracs(f) * geom(k)%length, outer, reps(f, k), err, &
                             label=trim(names(k)), ntheta=test_ntheta)
            if (allocated(err)) msgs(f, k) = err%message
         end do
      end do
      !$omp end parallel do
      do f = 1, size(fracs)
         worst = 0.0_wp
         do k = 1, nshape
            if (len_trim(msgs(f, k)) > 0) then
               call fatal_error(error, trim(msgs(f, k)))
               return
            end if
            worst = max(worst, reps(f, k)%fit_residual / reps(f, k)%thickness)
         end do
         write (output_unit, '(4x,a,f6.3,a,i0,a,i0,a,i0,a,i0,a,es9.2)') "t/L", fracs(f), ": fallback directions ", &
            sum(reps(f, :)%fallback), " of ", sum(reps(f, :)%directions), " (max per shape ", maxval(reps(f, :)%fallback), &
            "), orders up to ", maxval(reps(f, :)%order), ", max fit residual/t ", worst
      end do
      do k = 1, nshape
         do f = 2, size(fracs)
            call check(error, reps(f, k)%outer_volume > reps(f - 1, k)%outer_volume, &
                       trim(names(k))//": outer volume must grow with t")
            if (allocated(error)) return
         end do
      end do
   end subroutine test_all_coarse

   !> R_t at the nodes (sampled start, Newton, continuation) against `offset_radius`, whose Newton
   !> roots are validated by a distance search over the surface and which falls back on the
   !> definition itself: every node of every third meridian, three particles, three thicknesses.
   subroutine test_grid_reference(error)
      type(error_type), allocatable, intent(out) :: error
      type(sh_expansion_type), allocatable :: shapes(:)
      character(len=64), allocatable :: names(:)
      type(shape_geometry_type), allocatable :: geom(:)
      type(shell_surface_type) :: surf
      type(offset_counts_type) :: counts
      real(wp), parameter :: fracs(3) = [0.001_wp, 0.02_wp, 0.1_wp]
      real(wp), allocatable :: rt(:, :)
      real(wp) :: t, ref, worst
      integer :: k, f, i, j, nfar, ntot
      logical :: fb

      call coarse_shapes(3, shapes, names, geom, error)
      if (allocated(error)) return
      allocate (rt(test_ntheta, 2 * test_ntheta))
      do k = 1, size(shapes)
         call new_shell_surface(surf, shapes(k), test_ntheta, 2 * test_degree)
         do f = 1, size(fracs)
            t = fracs(f) * geom(k)%length
            call offset_grid(surf, t, rt, counts)
            worst = 0.0_wp
            nfar = 0
            ntot = 0
            do j = 1, 2 * test_ntheta, 3
               do i = 1, test_ntheta
                  call offset_radius(surf, surf%grid%sphere%theta(i), surf%grid%sphere%phi(j), t, ref, fb)
                  worst = max(worst, abs(rt(i, j) - ref) / t)
                  if (abs(rt(i, j) - ref) > 1.0e-6_wp * t) nfar = nfar + 1
                  ntot = ntot + 1
               end do
            end do
            write (output_unit, '(4x,a,a,f6.3,a,es9.2,a,i0,a,i0,a,i0,a,i0)') trim(names(k)), " t/L", fracs(f), &
               ": max |R - ref|/t", worst, ", nodes off by > 1e-6 t: ", nfar, " of ", ntot, &
               "; continued ", counts%continued, ", fallback ", counts%fallback
            call check(error, worst, 0.0_wp, trim(names(k))//" grid vs reference", thr=1.0e-2_wp)
            if (allocated(error)) return
            call check(error, real(nfar, wp) / ntot, 0.0_wp, trim(names(k))//" nodes off the reference", thr=1.0e-2_wp)
            if (allocated(error)) return
         end do
      end do
   end subroutine test_grid_reference

   !> Synthetic shapes (generator defaults, degrees 14 and 20, three shapes each) get shells of
   !> 0.5, 2, 5 and 10 % of their length on the default 120 x 240 grid, with the lifted fit
   !> inside R_t by at most the node bound.
   subroutine test_synthetic(error)
      type(error_type), allocatable, intent(out) :: error
      type(synthetic_params_type) :: par
      type(sh_expansion_type) :: shape, outer
      type(shape_geometry_type) :: geom
      type(shell_report_type) :: rep
      real(wp), parameter :: fracs(4) = [0.005_wp, 0.02_wp, 0.05_wp, 0.1_wp]
      integer, parameter :: degrees(2) = [14, 20]
      real(wp) :: vprev
      integer :: d, k, f

      do d = 1, size(degrees)
         par%nmax = degrees(d)
         do k = 1, 3
            call make_synthetic_shape(par, 2024_i8, k, shape, error)
            if (allocated(error)) return
            call compute_geometry(shape, geom)
            vprev = 0.0_wp
            do f = 1, size(fracs)
               call build_shell(shape, fracs(f) * geom%length, outer, rep, error, &
                                label="synthetic "//to_string(degrees(d))//"/"//to_string(k))
               if (allocated(error)) return
               write (output_unit, '(4x,a,i0,a,i0,a,f6.3,a,i0,a,i0,a,i0,a,i0,a,es9.2,a,es9.2)') "degree ", degrees(d), &
                  " shape ", k, " t/L", fracs(f), ": continued ", rep%continued, ", fallback ", rep%fallback, &
                  ", order ", rep%order, ", lifts ", rep%lifts, ", inside/t ", rep%fit_inside / rep%thickness, &
                  ", outside/t ", rep%fit_outside / rep%thickness
               call check(error, rep%fit_inside / rep%thickness <= node_inside_bound, "synthetic inside bound")
               if (allocated(error)) return
               call check(error, rep%outer_volume > vprev, "synthetic outer volume must grow with t")
               if (allocated(error)) return
               vprev = rep%outer_volume
            end do
         end do
      end do
   end subroutine test_synthetic

   !> The fitted (lifted) outer surface against the exact R_t (`offset_radius`) at random
   !> directions: it lies inside R_t by at most inside_bound t; real and synthetic shapes.
   subroutine test_fit_bound(error)
      type(error_type), allocatable, intent(out) :: error
      type(sh_expansion_type), allocatable :: shapes(:)
      character(len=64), allocatable :: names(:)
      type(shape_geometry_type), allocatable :: geom(:)
      type(synthetic_params_type) :: par
      type(shell_surface_type) :: surf
      type(sh_expansion_type) :: outer
      type(shell_report_type) :: rep
      type(rng_type) :: rng
      real(wp), parameter :: fracs(3) = [0.005_wp, 0.02_wp, 0.1_wp]
      real(wp) :: t, u(3), ref, inside, outside
      integer :: k, f, i
      logical :: fb

      call coarse_shapes(3, shapes, names, geom, error)
      if (allocated(error)) return
      par%nmax = test_degree
      ! the third real shape is replaced by a synthetic one
      call make_synthetic_shape(par, 2024_i8, 2, shapes(3), error)
      if (allocated(error)) return
      names(3) = "synthetic 14/2"
      call compute_geometry(shapes(3), geom(3))
      call new_rng(rng, 5_i8, 3_i8)
      do k = 1, size(shapes)
         call new_shell_surface(surf, shapes(k), test_ntheta, test_degree)
         do f = 1, size(fracs)
            t = fracs(f) * geom(k)%length
            call build_shell(shapes(k), t, outer, rep, error, label=trim(names(k)))
            if (allocated(error)) return
            inside = 0.0_wp
            outside = 0.0_wp
            do i = 1, 200
               u = [rng%normal(), rng%normal(), rng%normal()]
               u = u / norm2(u)
               call offset_radius(surf, acos(u(3)), atan2(u(2), u(1)), t, ref, fb)
               inside = max(inside, (ref - outer%radius_dir(u)) / t)
               outside = max(outside, (outer%radius_dir(u) - ref) / t)
            end do
            write (output_unit, '(4x,a,a,f6.3,a,es9.2,a,es9.2,a,es9.2,a,es9.2)') trim(names(k)), " t/L", fracs(f), &
               ": random directions inside/t", inside, ", outside/t", outside, "; nodes inside/t", &
               rep%fit_inside / t, ", outside/t", rep%fit_outside / t
            call check(error, rep%fit_inside / t <= node_inside_bound, trim(names(k))//" node inside bound")
            if (allocated(error)) return
            call check(error, inside, 0.0_wp, trim(names(k))//" t/L = "//to_string(fracs(f))//" inside bound", &
                       thr=inside_bound)
            if (allocated(error)) return
         end do
      end do
   end subroutine test_fit_bound

   subroutine test_layers(error)
      type(error_type), allocatable, intent(out) :: error
      type(sh_expansion_type), allocatable :: outers(:)
      type(shell_report_type), allocatable :: reps(:)
      real(wp), parameter :: rad = 2.0_wp, ts(3) = [0.1_wp, 0.3_wp, 0.6_wp]
      type(error_type), allocatable :: err
      real(wp) :: vol
      integer :: k

      call build_layers(sphere_shape(rad), ts, outers, reps, error, label="sphere", ntheta=16)
      if (allocated(error)) return
      do k = 1, size(ts)
         if (k == 1) then
            vol = 4.0_wp / 3.0_wp * pi * ((rad + ts(1))**3 - rad**3)
         else
            vol = 4.0_wp / 3.0_wp * pi * ((rad + ts(k))**3 - (rad + ts(k - 1))**3)
         end if
         call check(error, reps(k)%layer_volume, vol, "layer "//to_string(k), rel=1.0e-10_wp)
         if (allocated(error)) return
      end do
      call check(error, sum(reps%layer_fraction), reps(3)%shell_fraction, "layer fractions", rel=1.0e-10_wp)
      if (allocated(error)) return
      call check(error, reps(3)%shell_fraction, 1.0_wp - rad**3 / (rad + ts(3))**3, "shell fraction", rel=1.0e-10_wp)
      if (allocated(error)) return
      call build_layers(sphere_shape(rad), [0.3_wp, 0.1_wp], outers, reps, err, label="sphere", ntheta=16)
      call check(error, allocated(err), "decreasing layer thicknesses must be refused")
   end subroutine test_layers

   subroutine test_thickness_spec(error)
      type(error_type), allocatable, intent(out) :: error
      call check(error, thickness_in_shape_units(thickness_spec_type(0.5_wp, thickness_unit%mm), 20.0_wp, 0.25_wp), &
                 2.0_wp, "mm")
      if (allocated(error)) return
      call check(error, thickness_in_shape_units(thickness_spec_type(0.02_wp, thickness_unit%fraction_of_length), &
                                                 20.0_wp, 0.25_wp), 0.4_wp, "fraction of length")
      if (allocated(error)) return
      call check(error, thickness_in_shape_units(thickness_spec_type(0.5_wp, 99), 20.0_wp, 1.0_wp) < 0.0_wp, &
                 "unknown unit must give a negative thickness")
   end subroutine test_thickness_spec

   subroutine test_zero_thickness(error)
      type(error_type), allocatable, intent(out) :: error
      type(sh_expansion_type) :: outer
      type(shell_report_type) :: rep
      call build_shell(sphere_shape(1.0_wp), 0.0_wp, outer, rep, error, label="sphere", ntheta=16)
   end subroutine test_zero_thickness

   subroutine test_negative_message(error)
      type(error_type), allocatable, intent(out) :: error
      type(error_type), allocatable :: err
      type(sh_expansion_type) :: outer
      type(shell_report_type) :: rep
      call build_shell(sphere_shape(1.0_wp), -0.5_wp, outer, rep, err, label="grain-42", ntheta=16)
      call check(error, allocated(err), "negative thickness must fail")
      if (allocated(error)) return
      call check(error, index(err%message, "grain-42") > 0 .and. index(err%message, "-0.5") > 0, &
                 "message must name the particle and the thickness: "//err%message)
   end subroutine test_negative_message
end module test_shells
