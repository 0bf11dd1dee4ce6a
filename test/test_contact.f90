!> Tests of particle contact against outside truth: spheres (exact, to 1e-9 of tangency),
!> ellipsoids against the Perram-Wertheim contact function implemented here, real NIST shapes
!> against a dense brute-force reference, walls against exact ellipsoid extents, the Newton-Raphson
!> baseline, and the certified bounds of the patch hierarchy against dense sampling.
module test_contact
   use, intrinsic :: iso_fortran_env, only: output_unit
   use anm_core_kinds, only: wp, pi, two_pi, i8
   use anm_core_error, only: error_type, fatal_error
   use anm_core_random, only: rng_type, new_rng
   use anm_core_strings, only: to_string
   use anm_sh_expansion, only: sh_expansion_type
   use anm_shapes_library, only: load_shape_file
   use anm_shapes_analytic, only: sphere_shape, ellipsoid_shape, ellipsoid_radius
   use anm_geometry_rotation, only: random_rotation, world_to_body, body_to_world
   use anm_contact_body, only: contact_body_type, new_contact_body, leaf_level, stored_level, patch_rows, &
      & patch_cols, patch_index, patch_geometry, patch_bounds, slope_bound, nd_c, nd_e, nd_h, nd_r, nd_rc, nd_dir, &
      & support_bound, support_cell
   use anm_contact_overlap, only: contact_method, contact_params_type, bodies_overlap, overlap_early, overlap_depth, &
      & body_crosses_walls, sector_range, boxes_disjoint
   use anm_contact_studies, only: thesis_overlap_depth
   use anm_testing, only: unittest_type, new_unittest, check, shapes_dir
   implicit none
   private
   public :: collect_contact

   !> Ellipsoid expansion order and the relative band |d/d* - 1| excluded around tangency.
   integer, parameter :: ell_order = 24
   real(wp), parameter :: ell_band = 0.01_wp

   !> Dense surface points of one shape (3, npoint).
   type :: real_pts_type
      real(wp), allocatable :: p(:, :)
   end type real_pts_type

contains

   !> Tests of this suite.
   subroutine collect_contact(tests)
      type(unittest_type), allocatable, intent(out) :: tests(:)
      tests = [ &
              new_unittest("patch bounds contain densely sampled r", test_patch_bounds), &
              new_unittest("deep patch bounds and local slope bounds hold", test_local_bounds), &
              new_unittest("sector distance range holds and is attained", test_sector_range), &
              new_unittest("surface boxes contain the surface and are thin", test_surface_boxes), &
              new_unittest("box separation test against plain projections", test_boxes_disjoint), &
              new_unittest("support tables bound the support function and are tight", test_support_table), &
              new_unittest("support-table stages decide as the test without them", test_support_stages), &
              new_unittest("first stages alone prove only true overlaps (Perram-Wertheim, real shapes)", &
                           test_early_stages), &
              new_unittest("certified gap resolution on sphere and ellipsoid pairs", test_certified_gap), &
              new_unittest("spheres: exact decision to 1e-9 of tangency", test_spheres), &
              new_unittest("ellipsoids agree with Perram-Wertheim", test_ellipsoids), &
              new_unittest("real shapes against dense brute force", test_real_shapes), &
              new_unittest("walls against exact ellipsoid extents", test_walls), &
              new_unittest("Newton-Raphson baseline on spheres and ellipsoids", test_newton_raphson), &
              new_unittest("thesis' N_box reading: exact D_overlap of spheres, ellipsoids near the engine's", &
                           test_thesis_nbox), &
              new_unittest("gap margin: spheres exact to 1e-9, sphere-ellipsoid exact distance", test_margin_exact), &
              new_unittest("gap margin: real shapes against dense point distances", test_margin_real), &
              new_unittest("gap margin against walls: exact ellipsoid extents", test_margin_walls)]
   end subroutine collect_contact

   !> The support table (`support_bound`) against the support function sampled on dense surface
   !> points, h(v) >= max_k x_k . v for every direction v: a sphere (h = r exactly), an ellipsoid
   !> and two real shapes at orders 5 and 14, 5,000 random directions each (45,000 surface
   !> points). Never below a sampled projection (certified), and tight: on average at most 2 % of
   !> r_max above the sampled maximum (0.5-1.3 % measured),
   !> everywhere at most 10 % (cells where the support point jumps between two surface points).
   subroutine test_support_table(error)
      type(error_type), allocatable, intent(out) :: error
      character(len=:), allocatable :: dir
      type(sh_expansion_type) :: shape
      type(contact_body_type) :: body
      type(rng_type) :: rng
      real(wp), allocatable :: pts(:, :)
      real(wp) :: v(3), h, hs, slack, mean
      integer :: ic, n
      character(len=40) :: label
      call shapes_dir(dir, error)
      if (allocated(error)) return
      call new_rng(rng, 77_i8, 1_i8)
      do ic = 1, 5
         select case (ic)
         case (1)
            shape = sphere_shape(1.3_wp)
            label = "sphere r = 1.3"
         case (2)
            shape = ellipsoid_shape(2.0_wp, 1.2_wp, 0.7_wp, 12)
            label = "ellipsoid 2 x 1.2 x 0.7, degree 12"
         case (3, 4)
            call load_shape_file(dir//"/MA107-6-fine/MA107-6-fine-anm-00002.dat", shape, error)
            label = "MA107-6-fine-anm-00002"
         case (5)
            call load_shape_file(dir//"/MA111-7-coarse/MA111-7-coarse-anm-00009.dat", shape, error)
            label = "MA111-7-coarse-anm-00009"
         end select
         if (allocated(error)) return
         call new_contact_body(body, shape, error, nused=merge(5, min(14, shape%nmax), ic == 3))
         if (allocated(error)) return
         call dense_points(body%shape, 150, pts)
         slack = 0.0_wp
         mean = 0.0_wp
         do n = 1, 5000
            v = [rng%normal(), rng%normal(), rng%normal()]
            v = v / norm2(v)
            h = support_bound(body, v, support_cell(v))
            hs = maxval(matmul(v, pts))
            if (h < hs) then
               call fatal_error(error, trim(label)//": support bound "//to_string(h)//" below a surface point's " &
                                //"projection "//to_string(hs))
               return
            end if
            slack = max(slack, (h - hs) / body%r_max)
            mean = mean + (h - hs) / body%r_max / 5000
         end do
         write (output_unit, '(4x,a,a,i0,a,f7.4,a,f7.4)') trim(label), ", order ", body%nmax, &
            ": (bound - sampled support) / r_max mean ", mean, ", largest ", slack
         call check(error, mean < 0.02_wp .and. slack < 0.1_wp, trim(label)//": support table loose")
         if (allocated(error)) return
      end do
   end subroutine test_support_table

   !> The stages that read the support tables (separation along the line of centres, the
   !> furthest-reaching surface points tested inside the other body, separating planes of other
   !> normals) change no answer: certified tests of bodies with their tables against the same
   !> bodies without them (the earlier stages only), 6,000 pairs of real shapes at orders 5 and
   !> 14, random orientations, centre distances from the sum of the r_min to the sum of the r_max;
   !> then 1,600 pairs near contact (1 % inside to 3 % outside the contact distance along their
   !> direction). The new stages must also decide a good share of the pairs.
   subroutine test_support_stages(error)
      type(error_type), allocatable, intent(out) :: error
      integer, parameter :: nshape = 3
      character(len=*), parameter :: files(nshape) = [character(len=48) :: &
         "/MA107-6-fine/MA107-6-fine-anm-00002.dat", "/MA107-6-fine/MA107-6-fine-anm-00017.dat", &
         "/MA111-7-coarse/MA111-7-coarse-anm-00009.dat"]
      character(len=:), allocatable :: dir
      type(sh_expansion_type) :: shape
      type(contact_body_type) :: with(nshape), without(nshape)
      type(contact_params_type) :: cert
      type(rng_type) :: rng
      real(wp) :: rota(3, 3), rotb(3, 3), u(3), ca(3), cb(3), t, sa, sb, lo, hi, va(3), vb(3)
      integer :: io, k, n, ia, ib, nhit, ndiff, nsep
      logical :: h1, h0
      integer, parameter :: orders(2) = [5, 14]
      real(wp), parameter :: near(4) = [-0.01_wp, 0.003_wp, 0.01_wp, 0.03_wp]
      call shapes_dir(dir, error)
      if (allocated(error)) return
      cert%certified = .true.
      call new_rng(rng, 91_i8, 3_i8)
      do io = 1, size(orders)
         do k = 1, nshape
            call load_shape_file(dir//trim(files(k)), shape, error)
            if (allocated(error)) return
            call new_contact_body(with(k), shape, error, nused=orders(io))
            if (allocated(error)) return
            without(k) = with(k)
            deallocate (without(k)%supp)
         end do
         nhit = 0
         ndiff = 0
         nsep = 0
         ca = 0.0_wp
         do n = 1, 3000
            ia = 1 + mod(n, nshape)
            ib = 1 + mod(n / nshape, nshape)
            rota = random_rotation(rng)
            rotb = random_rotation(rng)
            u = [rng%normal(), rng%normal(), rng%normal()]
            u = u / norm2(u)
            sa = 0.5_wp + rng%uniform()
            sb = 0.5_wp + rng%uniform()
            lo = sa * with(ia)%r_min + sb * with(ib)%r_min
            hi = sa * with(ia)%r_max + sb * with(ib)%r_max
            t = rng%uniform()
            cb = (lo + (hi - lo) * t) * u
            h1 = bodies_overlap(with(ia), ca, rota, sa, with(ib), cb, rotb, sb, cert)
            h0 = bodies_overlap(without(ia), ca, rota, sa, without(ib), cb, rotb, sb, cert)
            if (h0) nhit = nhit + 1
            if (h1 .neqv. h0) ndiff = ndiff + 1
            ! which pairs the new stages decide (their own tests, as bodies_overlap applies them)
            va = matmul(u, rota)
            vb = -matmul(u, rotb)
            if (sa * support_bound(with(ia), va, support_cell(va)) &
                + sb * support_bound(with(ib), vb, support_cell(vb)) < norm2(cb)) nsep = nsep + 1
         end do
         write (output_unit, '(4x,a,i0,a,i0,a,i0,a,i0)') "order ", orders(io), ": 3000 pairs, ", nhit, &
            " overlapping, separated by the support tables ", nsep, ", answers differing ", ndiff
         call check(error, ndiff == 0, "support-table stages changed "//to_string(ndiff)//" answers at order " &
                    //to_string(orders(io)))
         if (allocated(error)) return
         call check(error, nsep > 300, "support tables separated only "//to_string(nsep)//" pairs")
         if (allocated(error)) return
         ! near contact, where the plane search of stage 2c acts: the contact distance d* along u by
         ! bisection, then the pair at d* (1 + delta), delta from 1 % inside to 3 % outside
         ndiff = 0
         nsep = 0
         do n = 1, 200
            ia = 1 + mod(n, nshape)
            ib = 1 + mod(n / nshape, nshape)
            rota = random_rotation(rng)
            rotb = random_rotation(rng)
            u = [rng%normal(), rng%normal(), rng%normal()]
            u = u / norm2(u)
            sa = 1.0_wp
            sb = 0.6_wp + 0.8_wp * rng%uniform()
            lo = sa * with(ia)%r_min + sb * with(ib)%r_min
            hi = sa * with(ia)%r_max + sb * with(ib)%r_max
            do k = 1, 30
               t = 0.5_wp * (lo + hi)
               if (bodies_overlap(without(ia), ca, rota, sa, without(ib), t * u, rotb, sb, cert)) then
                  lo = t
               else
                  hi = t
               end if
            end do
            do k = 1, size(near)
               cb = hi * (1.0_wp + near(k)) * u
               h1 = bodies_overlap(with(ia), ca, rota, sa, with(ib), cb, rotb, sb, cert)
               h0 = bodies_overlap(without(ia), ca, rota, sa, without(ib), cb, rotb, sb, cert)
               if (.not. h0) nsep = nsep + 1
               if (h1 .neqv. h0) ndiff = ndiff + 1
            end do
         end do
         write (output_unit, '(4x,a,i0,a,i0,a,i0)') "order ", orders(io), ": 800 pairs near contact, ", nsep, &
            " apart, answers differing ", ndiff
         call check(error, ndiff == 0, "support-table stages changed "//to_string(ndiff)//" answers near contact " &
                    //"at order "//to_string(orders(io)))
         if (allocated(error)) return
      end do
   end subroutine test_support_stages

   !> `sector_range` against sampled sector points: 20,000 random sectors (half-angles up to 1.2
   !> rad, points q anywhere, often near the sector), 64 points each (a quarter on the rim); no
   !> sampled distance may leave [smin, smax], and the sampled extremes must come close to them.
   subroutine test_sector_range(error)
      type(error_type), allocatable, intent(out) :: error
      integer, parameter :: nsector = 20000, npoint = 64
      type(rng_type) :: rng
      integer :: n, k, nbad
      real(wp) :: dir(3), e1(3), e2(3), alpha, rlo, rhi, q(3), smin, smax, v(3), s, w, rho, dist, dlo, dhi, &
                  slack, worst
      call new_rng(rng, 2024_i8, 11_i8)
      nbad = 0
      worst = 0.0_wp
      do n = 1, nsector
         dir = [rng%normal(), rng%normal(), rng%normal()]
         dir = dir / norm2(dir)
         e1 = [dir(2), -dir(1), 0.0_wp]
         if (norm2(e1) < 0.1_wp) e1 = [0.0_wp, dir(3), -dir(2)]
         e1 = e1 / norm2(e1)
         e2 = [dir(2) * e1(3) - dir(3) * e1(2), dir(3) * e1(1) - dir(1) * e1(3), dir(1) * e1(2) - dir(2) * e1(1)]
         alpha = 1.2_wp * rng%uniform()**2 + 1.0e-4_wp
         rlo = 0.5_wp + rng%uniform()
         rhi = rlo + 0.5_wp * rng%uniform()
         q = 3.0_wp * [rng%normal(), rng%normal(), rng%normal()]
         if (mod(n, 2) == 0) q = (rlo + (rhi - rlo) * rng%uniform()) * dir + 0.3_wp * q
         call sector_range(q, dir, cos(alpha), sin(alpha), rlo, rhi, smin, smax)
         dlo = huge(1.0_wp)
         dhi = 0.0_wp
         do k = 1, npoint
            w = two_pi * rng%uniform()
            s = alpha * sqrt(rng%uniform())
            rho = rlo + (rhi - rlo) * rng%uniform()
            if (mod(k, 4) == 0) then
               s = alpha
               rho = merge(rlo, rhi, rng%uniform() < 0.5_wp)
            end if
            v = cos(s) * dir + sin(s) * (cos(w) * e1 + sin(w) * e2)
            dist = norm2(rho * v - q)
            dlo = min(dlo, dist)
            dhi = max(dhi, dist)
            if (dist < smin * (1.0_wp - 1.0e-12_wp) .or. dist > smax * (1.0_wp + 1.0e-12_wp)) nbad = nbad + 1
         end do
         ! attained: the sampled range approaches [smin, smax] (random sampling, small sectors)
         if (alpha < 0.05_wp) then
            slack = max(dlo - smin, smax - dhi) / (rhi + alpha * rhi)
            worst = max(worst, slack)
         end if
      end do
      write (output_unit, '(4x,a,i0,a,es10.2)') "sector range: points outside the bound ", nbad, &
         "; largest gap to sampled extremes (half-angle < 0.05, relative to the sector size) ", worst
      call check(error, nbad, 0)
      if (allocated(error)) return
      call check(error, worst < 0.2_wp, "sector range far from the sampled extremes")
   end subroutine test_sector_range

   subroutine test_patch_bounds(error)
      type(error_type), allocatable, intent(out) :: error
      character(len=:), allocatable :: dir
      type(sh_expansion_type) :: shape
      type(contact_body_type) :: body
      type(rng_type) :: rng
      integer :: n, k, i, j, l, ip
      real(wp) :: th, ph, r, u(3)
      call shapes_dir(dir, error)
      if (allocated(error)) return
      call load_shape_file(dir//"/MA111-7-coarse/MA111-7-coarse-anm-00009.dat", shape, error)
      if (allocated(error)) return
      call new_contact_body(body, shape, error, nused=14)
      if (allocated(error)) return
      call new_rng(rng, 7_i8, 1_i8)
      ! random points: each must be within the bounds of its patch at every stored level
      do n = 1, 200000
         th = acos(2.0_wp * rng%uniform() - 1.0_wp)
         ph = two_pi * rng%uniform()
         u = [sin(th) * cos(ph), sin(th) * sin(ph), cos(th)]
         r = body%shape%radius_dir(u)
         do l = 0, leaf_level
            i = min(patch_rows(l), int(th / pi * patch_rows(l)) + 1)
            j = min(patch_cols(l), int(ph / two_pi * patch_cols(l)) + 1)
            k = patch_index(body, l, i, j)
            ip = k
            if (r > body%rhi(ip) .or. r < body%rlo(ip)) then
               call fatal_error(error, "r = "//to_string(r)//" outside patch bounds ["//to_string(body%rlo(ip)) &
                                //", "//to_string(body%rhi(ip))//"] at level "//to_string(l))
               return
            end if
            if (acos(min(1.0_wp, dot_product(u, body%dir(:, k)))) > atan2(body%sina(k), body%cosa(k))) then
               call fatal_error(error, "direction outside its patch cap at level "//to_string(l))
               return
            end if
         end do
      end do
      ! the box bound contains the N_ext scan box and the bounds are not absurdly loose
      call check(error, all(body%box_hi >= body%ext_hi) .and. all(body%box_lo <= body%ext_lo), &
                 "certified box must contain the N_ext scan box")
      if (allocated(error)) return
      write (output_unit, '(a,4f9.4)') "    r_min, r_max (certified), leaf mean width, Lipschitz/r_max: ", &
         body%r_min, body%r_max, sum(body%rhi(body%off(leaf_level) + 1:) - body%rlo(body%off(leaf_level) + 1:)) &
         / (body%off(leaf_level + 1) - body%off(leaf_level)), body%lipschitz / body%r_max
      call check(error, body%r_max - body%r_min < 0.9_wp * body%r_max, "certified radial bounds too loose")
   end subroutine test_patch_bounds

   !> Stored bounds of levels leaf_level+1..stored_level and their table caps contain r at random
   !> directions; radius_slope agrees with radius_dir and finite differences; the local bound
   !> |r(u) - r(u0)| <= slope_bound(g0, alpha) holds for random u within alpha of random u0.
   subroutine test_local_bounds(error)
      type(error_type), allocatable, intent(out) :: error
      character(len=:), allocatable :: dir
      type(sh_expansion_type) :: shape
      type(contact_body_type) :: body
      type(rng_type) :: rng
      integer :: n, i, j, l, io, nord
      integer, parameter :: orders(2) = [14, 30]
      real(wp) :: th, ph, r, u(3), d(3), cosa, sina, rlo, rhi, r0, g0, alpha, v(3), t1(3), t2(3), ang, w, &
         gfd, h, worst
      call shapes_dir(dir, error)
      if (allocated(error)) return
      call load_shape_file(dir//"/MA111-7-coarse/MA111-7-coarse-anm-00035.dat", shape, error)
      if (allocated(error)) return
      do io = 1, size(orders)
         nord = orders(io)
         call new_contact_body(body, shape, error, nused=nord)
         if (allocated(error)) return
         call new_rng(rng, 17_i8, int(nord, i8))
         worst = 0.0_wp
         do n = 1, 100000
            th = acos(2.0_wp * rng%uniform() - 1.0_wp)
            ph = two_pi * rng%uniform()
            u = [sin(th) * cos(ph), sin(th) * sin(ph), cos(th)]
            r = body%shape%radius_dir(u)
            do l = leaf_level + 1, stored_level
               i = min(patch_rows(l), int(th / pi * patch_rows(l)) + 1)
               j = min(patch_cols(l), int(ph / two_pi * patch_cols(l)) + 1)
               call patch_bounds(body, l, i, j, rlo, rhi)
               call patch_geometry(body, l, i, j, d, cosa, sina)
               if (r > rhi .or. r < rlo) then
                  call fatal_error(error, "r = "//to_string(r)//" outside stored bounds at level "//to_string(l))
                  return
               end if
               if (dot_product(u, d) < cosa) then
                  call fatal_error(error, "direction outside its table cap at level "//to_string(l))
                  return
               end if
            end do
            ! radius_slope: value and gradient norm (central differences along two tangents)
            call body%shape%radius_slope(u, r0, g0)
            if (abs(r0 - r) > 1.0e-10_wp * body%r_max) then
               call fatal_error(error, "radius_slope r differs from radius_dir")
               return
            end if
            if (mod(n, 10) == 0 .and. sin(th) > 0.05_wp) then
               h = 1.0e-6_wp
               gfd = sqrt(((body%shape%radius(th + h, ph) - body%shape%radius(th - h, ph)) / (2 * h))**2 + &
                          ((body%shape%radius(th, ph + h) - body%shape%radius(th, ph - h)) / (2 * h * sin(th)))**2)
               if (abs(gfd - g0) > 1.0e-5_wp * body%lipschitz) then
                  call fatal_error(error, "radius_slope gradient "//to_string(g0)//" vs finite differences " &
                                   //to_string(gfd))
                  return
               end if
            end if
            ! local bound: random v at angle <= alpha from u
            alpha = 0.05_wp * rng%uniform()**2
            t1 = [cos(th) * cos(ph), cos(th) * sin(ph), -sin(th)]
            t2 = [-sin(ph), cos(ph), 0.0_wp]
            ang = two_pi * rng%uniform()
            v = cos(alpha) * u + sin(alpha) * (cos(ang) * t1 + sin(ang) * t2)
            w = slope_bound(body, g0, alpha, sin(th))
            if (abs(body%shape%radius_dir(v) - r0) > w) then
               call fatal_error(error, "local slope bound violated at alpha "//to_string(alpha))
               return
            end if
            if (alpha > 1.0e-3_wp) worst = max(worst, abs(body%shape%radius_dir(v) - r0) / w)
         end do
         write (output_unit, '(a,i0,a,f6.3)') "    order ", nord, ": largest |r(u) - r(u0)| / local bound (alpha > 1e-3) ", worst
      end do
   end subroutine test_local_bounds

   !> The oriented boxes of the surface pieces (levels 0..leaf_level, `body%node`) contain the
   !> surface at 200,000 random directions for degrees 14 and 30; the stored centre radius is r at
   !> the cap centre; the leaf boxes are thin: mean half-thickness below 0.003 r_max (the second
   !> order certification gives 6e-4 and 1.2e-3 here, first order alone 1.7e-3 and 6.6e-3).
   subroutine test_surface_boxes(error)
      type(error_type), allocatable, intent(out) :: error
      character(len=:), allocatable :: dir
      type(sh_expansion_type) :: shape
      type(contact_body_type) :: body
      type(rng_type) :: rng
      integer, parameter :: orders(2) = [14, 30]
      integer :: io, n, l, i, j, k
      real(wp) :: th, ph, u(3), x(3), q(3), e(3, 3), worst, thick
      call shapes_dir(dir, error)
      if (allocated(error)) return
      call load_shape_file(dir//"/MA111-7-coarse/MA111-7-coarse-anm-00009.dat", shape, error)
      if (allocated(error)) return
      do io = 1, size(orders)
         call new_contact_body(body, shape, error, nused=orders(io))
         if (allocated(error)) return
         call new_rng(rng, 31_i8, int(orders(io), i8))
         worst = 0.0_wp
         do n = 1, 200000
            th = acos(2.0_wp * rng%uniform() - 1.0_wp)
            ph = two_pi * rng%uniform()
            u = [sin(th) * cos(ph), sin(th) * sin(ph), cos(th)]
            x = body%shape%radius_dir(u) * u
            do l = 0, leaf_level
               i = min(patch_rows(l), int(th / pi * patch_rows(l)) + 1)
               j = min(patch_cols(l), int(ph / two_pi * patch_cols(l)) + 1)
               k = patch_index(body, l, i, j)
               e = reshape(body%node(nd_e:nd_e + 8, k), [3, 3])
               q = abs(matmul(x - body%node(nd_c:nd_c + 2, k), e)) / body%node(nd_h:nd_h + 2, k)
               worst = max(worst, maxval(q))
               if (any(q > 1.0_wp)) then
                  call fatal_error(error, "surface point outside its patch box at level "//to_string(l)//", order " &
                                   //to_string(orders(io)))
                  return
               end if
               if (norm2(x - body%node(nd_c:nd_c + 2, k)) > body%node(nd_r, k)) then
                  call fatal_error(error, "surface point outside its patch box ball")
                  return
               end if
            end do
         end do
         do k = 1, body%off(leaf_level + 1)
            if (abs(body%node(nd_rc, k) - body%shape%radius_dir(body%node(nd_dir:nd_dir + 2, k))) > 1.0e-10_wp * body%r_max) then
               call fatal_error(error, "stored centre radius differs from r at the cap centre")
               return
            end if
         end do
         thick = sum(body%node(nd_h + 2, body%off(leaf_level) + 1:body%off(leaf_level + 1))) &
                 / (body%off(leaf_level + 1) - body%off(leaf_level)) / body%r_max
         write (output_unit, '(a,i0,a,es10.3,a,f6.3)') "    order ", orders(io), ": mean leaf box half-thickness / r_max ", &
            thick, ", largest |e_i . (x - c)| / h_i ", worst
         call check(error, thick < 3.0e-3_wp, "leaf boxes too thick")
         if (allocated(error)) return
      end do
   end subroutine test_surface_boxes

   !> `boxes_disjoint` (scalarised separating axis test) against the plain test: each of the 15
   !> axes (face normals, edge cross products) normalised, both boxes projected on it. 20,000
   !> random pairs of boxes (one half-extent often thin, centres near touching); outside a
   !> relative band of 1e-9 around ties the answers must agree, and a "disjoint" answer is
   !> confirmed by 32 sampled points of each box lying outside the other.
   subroutine test_boxes_disjoint(error)
      type(error_type), allocatable, intent(out) :: error
      type(rng_type) :: rng
      real(wp) :: c1(3), c2(3), e1(3, 3), e2(3, 3), h1(3), h2(3), d(3), ax(3), best, s, ra, rb, p(3)
      integer :: n, i, j, m, nwrong, nsample_bad, nedge, ndisjoint
      logical :: got, ref, face
      call new_rng(rng, 41_i8, 3_i8)
      nwrong = 0
      nsample_bad = 0
      nedge = 0
      ndisjoint = 0
      do n = 1, 20000
         e1 = random_rotation(rng)
         e2 = random_rotation(rng)
         h1 = [0.1_wp + rng%uniform(), 0.1_wp + rng%uniform(), 0.001_wp + 0.5_wp * rng%uniform()]
         h2 = [0.1_wp + rng%uniform(), 0.1_wp + rng%uniform(), 0.001_wp + 0.5_wp * rng%uniform()]
         if (mod(n, 3) == 0) h2 = h2([3, 1, 2])
         c1 = [rng%normal(), rng%normal(), rng%normal()]
         d = [rng%normal(), rng%normal(), rng%normal()]
         c2 = c1 + d / norm2(d) * (norm2(h1) + norm2(h2)) * rng%uniform()
         d = c2 - c1
         ! plain test: the largest relative separation over the axes
         best = -huge(1.0_wp)
         face = .false.
         do m = 1, 15
            if (m <= 3) then
               ax = e1(:, m)
            else if (m <= 6) then
               ax = e2(:, m - 3)
            else
               i = (m - 7) / 3 + 1
               j = mod(m - 7, 3) + 1
               ax = [e1(2, i) * e2(3, j) - e1(3, i) * e2(2, j), e1(3, i) * e2(1, j) - e1(1, i) * e2(3, j), &
                     e1(1, i) * e2(2, j) - e1(2, i) * e2(1, j)]
               if (norm2(ax) < 1.0e-6_wp) cycle
               ax = ax / norm2(ax)
            end if
            ra = sum(h1 * abs(matmul(ax, e1)))
            rb = sum(h2 * abs(matmul(ax, e2)))
            s = (abs(dot_product(ax, d)) - ra - rb) / (ra + rb + norm2(d))
            if (m <= 6 .and. s > 0.0_wp) face = .true.
            best = max(best, s)
         end do
         ref = best > 0.0_wp
         got = boxes_disjoint(c1, e1, h1, norm2(h1) * (1.0_wp + 1.0e-12_wp), c2, e2, h2, &
                              norm2(h2) * (1.0_wp + 1.0e-12_wp))
         if (abs(best) > 1.0e-9_wp .and. (got .neqv. ref)) nwrong = nwrong + 1
         if (ref .and. .not. face) nedge = nedge + 1
         if (.not. got) cycle
         ndisjoint = ndisjoint + 1
         do m = 1, 32
            p = c1 + matmul(e1, h1 * [2.0_wp * rng%uniform() - 1.0_wp, 2.0_wp * rng%uniform() - 1.0_wp, &
                                      2.0_wp * rng%uniform() - 1.0_wp])
            if (all(abs(matmul(p - c2, e2)) <= h2)) nsample_bad = nsample_bad + 1
            p = c2 + matmul(e2, h2 * [2.0_wp * rng%uniform() - 1.0_wp, 2.0_wp * rng%uniform() - 1.0_wp, &
                                      2.0_wp * rng%uniform() - 1.0_wp])
            if (all(abs(matmul(p - c1, e1)) <= h1)) nsample_bad = nsample_bad + 1
         end do
      end do
      write (output_unit, '(a,i0,a,i0,a,i0,a,i0)') "    box pairs: disjoint ", ndisjoint, " (by an edge axis only ", &
         nedge, "), disagreements ", nwrong, ", sampled points inside the other box ", nsample_bad
      call check(error, nwrong, 0, "boxes_disjoint disagrees with the plain separating axis test")
      if (allocated(error)) return
      call check(error, nsample_bad, 0, "a box called disjoint holds a point of the other")
      if (allocated(error)) return
      call check(error, nedge > 100, "too few pairs separated by edge axes only to test them")
   end subroutine test_boxes_disjoint

   !> Certified mode against exact truth: spheres (gap exact) and ellipsoid pairs near tangency
   !> (the gap is at least (mu - 1)(a_min,A + a_min,B) when the Perram-Wertheim scaling factor is
   !> mu > 1). No missed overlap; contact reported for a separated pair only below the stated gap
   !> resolution gap x L.
   subroutine test_certified_gap(error)
      type(error_type), allocatable, intent(out) :: error
      real(wp), parameter :: ax(3) = [1.0_wp, 0.8_wp, 0.6_wp]
      type(contact_body_type) :: ell, sph
      type(contact_params_type) :: cert
      type(rng_type) :: rng
      type(sh_expansion_type) :: shape
      real(wp) :: rota(3, 3), rotb(3, 3), u(3), cb(3), f1, mu, lb, tol, err, lsph, dmax_fp
      integer :: n, nfn, nviol, nfp, nsep
      logical :: got
      shape = ellipsoid_shape(ax(1), ax(2), ax(3), ell_order)
      err = ellipsoid_error(shape, ax)
      call new_contact_body(ell, shape, error)
      if (allocated(error)) return
      call new_contact_body(sph, sphere_shape(1.0_wp), error)
      if (allocated(error)) return
      cert%certified = .true.
      call new_rng(rng, 31_i8, 7_i8)
      tol = cert%gap * maxval(ell%box_hi - ell%box_lo)
      nfn = 0
      nviol = 0
      nfp = 0
      nsep = 0
      dmax_fp = 0.0_wp
      do n = 1, 600
         rota = random_rotation(rng)
         rotb = random_rotation(rng)
         u = [rng%normal(), rng%normal(), rng%normal()]
         u = u / norm2(u)
         f1 = pw_function(rota, ax, rotb, ax, u)
         ! scaling factor mu in [0.997, 1.003]: contact distance along u times mu
         mu = 1.0_wp + 0.003_wp * (2.0_wp * rng%uniform() - 1.0_wp)
         cb = mu / sqrt(f1) * u
         got = bodies_overlap(ell, [0.0_wp, 0.0_wp, 0.0_wp], rota, 1.0_wp, ell, cb, rotb, 1.0_wp, cert)
         ! truncation error of the expansion: a band of 4 err around tangency is not judged
         lb = (mu - 1.0_wp) * 2.0_wp * minval(ax)
         if (mu < 1.0_wp .and. lb < -4.0_wp * err .and. .not. got) nfn = nfn + 1
         if (mu > 1.0_wp) then
            nsep = nsep + 1
            if (got) then
               nfp = nfp + 1
               dmax_fp = max(dmax_fp, lb)
               if (lb > tol + 4.0_wp * err) nviol = nviol + 1
            end if
         end if
      end do
      ! spheres: the gap is exact
      lsph = maxval(sph%box_hi - sph%box_lo)
      do n = 1, 2000
         rota = random_rotation(rng)
         u = [rng%normal(), rng%normal(), rng%normal()]
         u = u / norm2(u)
         lb = 3.0_wp * cert%gap * lsph * rng%uniform()
         got = bodies_overlap(sph, [0.0_wp, 0.0_wp, 0.0_wp], rota, 1.0_wp, sph, (2.0_wp + lb) * u, rota, 1.0_wp, cert)
         if (got .and. lb > cert%gap * lsph) nviol = nviol + 1
      end do
      write (output_unit, '(a,i0,a,i0,a,es9.2,a,es9.2)') "    ellipsoids within 0.3 % of contact: ", nsep, &
         " separated, ", nfp, " reported as contact (largest gap lower bound ", dmax_fp, ", stated gap x L ", tol
      call check(error, nfn, 0, "certified mode missed an overlap")
      if (allocated(error)) return
      call check(error, nviol, 0, "certified contact reported beyond the stated gap resolution")
   end subroutine test_certified_gap

   subroutine test_spheres(error)
      type(error_type), allocatable, intent(out) :: error
      type(contact_body_type) :: ba, bb
      type(contact_params_type) :: par, cert
      type(rng_type) :: rng
      real(wp) :: ra, rb, sa, sb, ca(3), cb(3), u(3), d, gap, rota(3, 3), rotb(3, 3)
      integer :: n, nbad
      logical :: expect
      call new_contact_body(ba, sphere_shape(1.0_wp), error)
      if (allocated(error)) return
      call new_contact_body(bb, sphere_shape(0.7_wp), error)
      if (allocated(error)) return
      cert%certified = .true.
      call new_rng(rng, 11_i8, 1_i8)
      nbad = 0
      do n = 1, 20000
         sa = 0.5_wp + rng%uniform()
         sb = 0.5_wp + 2.0_wp * rng%uniform()
         ra = sa * 1.0_wp
         rb = sb * 0.7_wp
         rota = random_rotation(rng)
         rotb = random_rotation(rng)
         u = [rng%normal(), rng%normal(), rng%normal()]
         u = u / norm2(u)
         select case (mod(n, 4))
         case (0)
            gap = 1.0e-9_wp
         case (1)
            gap = -1.0e-9_wp
         case default
            gap = (ra + rb) * (2.0_wp * rng%uniform() - 1.0_wp) * 10.0_wp**(-9.0_wp * rng%uniform())
         end select
         ca = [10.0_wp, 10.0_wp, 10.0_wp] + [rng%uniform(), rng%uniform(), rng%uniform()]
         cb = ca + (ra + rb + gap) * u
         d = norm2(cb - ca)
         expect = d < ra + rb
         if (bodies_overlap(ba, ca, rota, sa, bb, cb, rotb, sb, par) .neqv. expect) nbad = nbad + 1
         if (bodies_overlap(ba, ca, rota, sa, bb, cb, rotb, sb, cert) .neqv. expect) nbad = nbad + 1
      end do
      call check(error, nbad, 0, "wrong sphere decisions")
   end subroutine test_spheres

   !> Perram-Wertheim: overlap iff max_lambda lambda (1-lambda) r^T [(1-lambda) A^-1 ... ] < 1, written
   !> with A = R diag(a^2) R^T: F = max lambda(1-lambda) r^T ((1-lambda) A + lambda B)^-1 r.
   function pw_function(rot_a, sa, rot_b, sb, r) result(f)
      real(wp), intent(in) :: rot_a(3, 3), sa(3), rot_b(3, 3), sb(3), r(3)
      real(wp) :: f
      real(wp) :: ma(3, 3), mb(3, 3), x0, x1, x2, x3, f1, f2
      integer :: it
      real(wp), parameter :: gr = 0.6180339887498949_wp
      ma = matmul(rot_a, matmul(diag(sa**2), transpose(rot_a)))
      mb = matmul(rot_b, matmul(diag(sb**2), transpose(rot_b)))
      x0 = 0.0_wp
      x3 = 1.0_wp
      x1 = x3 - gr * (x3 - x0)
      x2 = x0 + gr * (x3 - x0)
      f1 = pw_value(x1)
      f2 = pw_value(x2)
      do it = 1, 80
         if (f1 < f2) then
            x0 = x1
            x1 = x2
            f1 = f2
            x2 = x0 + gr * (x3 - x0)
            f2 = pw_value(x2)
         else
            x3 = x2
            x2 = x1
            f2 = f1
            x1 = x3 - gr * (x3 - x0)
            f1 = pw_value(x1)
         end if
      end do
      f = max(f1, f2)
   contains
      function pw_value(lam) result(v)
         real(wp), intent(in) :: lam
         real(wp) :: v, c(3, 3)
         c = (1.0_wp - lam) * ma + lam * mb
         v = lam * (1.0_wp - lam) * dot_product(r, solve3(c, r))
      end function pw_value
   end function pw_function

   pure function diag(v) result(m)
      real(wp), intent(in) :: v(3)
      real(wp) :: m(3, 3)
      m = 0.0_wp
      m(1, 1) = v(1)
      m(2, 2) = v(2)
      m(3, 3) = v(3)
   end function diag

   pure function solve3(a, b) result(x)
      real(wp), intent(in) :: a(3, 3), b(3)
      real(wp) :: x(3), det, inv(3, 3)
      inv(1, 1) = a(2, 2) * a(3, 3) - a(2, 3) * a(3, 2)
      inv(1, 2) = a(1, 3) * a(3, 2) - a(1, 2) * a(3, 3)
      inv(1, 3) = a(1, 2) * a(2, 3) - a(1, 3) * a(2, 2)
      inv(2, 1) = a(2, 3) * a(3, 1) - a(2, 1) * a(3, 3)
      inv(2, 2) = a(1, 1) * a(3, 3) - a(1, 3) * a(3, 1)
      inv(2, 3) = a(1, 3) * a(2, 1) - a(1, 1) * a(2, 3)
      inv(3, 1) = a(2, 1) * a(3, 2) - a(2, 2) * a(3, 1)
      inv(3, 2) = a(1, 2) * a(3, 1) - a(1, 1) * a(3, 2)
      inv(3, 3) = a(1, 1) * a(2, 2) - a(1, 2) * a(2, 1)
      det = a(1, 1) * inv(1, 1) + a(1, 2) * inv(2, 1) + a(1, 3) * inv(3, 1)
      x = matmul(inv, b) / det
   end function solve3

   !> Largest |r_N - r_exact| of an expanded ellipsoid on a dense random sample.
   function ellipsoid_error(shape, ax) result(err)
      type(sh_expansion_type), intent(in) :: shape
      real(wp), intent(in) :: ax(3)
      real(wp) :: err, u(3)
      type(rng_type) :: rng
      integer :: n
      call new_rng(rng, 3_i8, 9_i8)
      err = 0.0_wp
      do n = 1, 20000
         u = [rng%normal(), rng%normal(), rng%normal()]
         u = u / norm2(u)
         err = max(err, abs(shape%radius_dir(u) - ellipsoid_radius(ax(1), ax(2), ax(3), u)))
      end do
   end function ellipsoid_error

   subroutine test_ellipsoids(error)
      type(error_type), allocatable, intent(out) :: error
      integer, parameter :: nell = 3
      real(wp), parameter :: axes(3, nell) = reshape([1.0_wp, 0.8_wp, 0.6_wp, 0.9_wp, 0.9_wp, 0.55_wp, &
                                                       1.1_wp, 0.7_wp, 0.7_wp], [3, nell])
      type(contact_body_type) :: body(nell)
      type(sh_expansion_type) :: shape
      type(contact_params_type) :: par, cert
      type(rng_type) :: rng
      real(wp) :: err(nell), rota(3, 3), rotb(3, 3), u(3), ca(3), cb(3), f1, dstar, delta
      integer :: k, n, ia, ib, nwrong, nwrong_cert, ntested, nband, nfp_cert
      logical :: expect
      do k = 1, nell
         shape = ellipsoid_shape(axes(1, k), axes(2, k), axes(3, k), ell_order)
         err(k) = ellipsoid_error(shape, axes(:, k))
         call new_contact_body(body(k), shape, error)
         if (allocated(error)) return
      end do
      cert%certified = .true.
      call new_rng(rng, 5_i8, 2_i8)
      nwrong = 0
      nwrong_cert = 0
      nfp_cert = 0
      ntested = 0
      nband = 0
      ca = [0.0_wp, 0.0_wp, 0.0_wp]
      do n = 1, 12000
         ia = 1 + mod(n, nell)
         ib = 1 + mod(n / nell, nell)
         rota = random_rotation(rng)
         rotb = random_rotation(rng)
         u = [rng%normal(), rng%normal(), rng%normal()]
         u = u / norm2(u)
         ! F scales with the square of the distance: the contact distance along u is 1/sqrt(F(u))
         f1 = pw_function(rota, axes(:, ia), rotb, axes(:, ib), u)
         dstar = 1.0_wp / sqrt(f1)
         delta = 0.2_wp * (2.0_wp * rng%uniform() - 1.0_wp)
         if (abs(delta) < ell_band) then
            nband = nband + 1
            cycle
         end if
         cb = ca + dstar * (1.0_wp + delta) * u
         expect = delta < 0.0_wp
         ntested = ntested + 1
         if (bodies_overlap(body(ia), ca, rota, 1.0_wp, body(ib), cb, rotb, 1.0_wp, par) .neqv. expect) &
            nwrong = nwrong + 1
         if (bodies_overlap(body(ia), ca, rota, 1.0_wp, body(ib), cb, rotb, 1.0_wp, cert)) then
            if (.not. expect) nfp_cert = nfp_cert + 1
         else
            if (expect) nwrong_cert = nwrong_cert + 1
         end if
      end do
      write (output_unit, '(a,i0,a,es9.2,a,f6.3,a,i0,a,i0,a,i0,a,i0)') "    order ", ell_order, &
         ", max |r_N - r_exact| = ", maxval(err), ", band |d/d*-1| < ", ell_band, ": tested ", ntested, &
         ", wrong (default) ", nwrong, &
         ", certified: false negatives ", nwrong_cert, ", false positives ", nfp_cert
      call check(error, ntested >= 10000, "fewer than 10000 ellipsoid pairs outside the band")
      if (allocated(error)) return
      call check(error, nwrong + nwrong_cert, 0, "ellipsoid decisions disagreeing with Perram-Wertheim")
      if (allocated(error)) return
      call check(error, nfp_cert <= ntested / 10, "certified false positives above 10%")
   end subroutine test_ellipsoids

   !> `overlap_early` (the first stages alone, which `packing%fits` runs over every candidate
   !> before it certifies any pair) against exact truth: ellipsoid pairs it calls overlapping
   !> overlap by Perram-Wertheim (outside a 1 % band around tangency, the expansion's error), and
   !> every pair it calls overlapping, of ellipsoids and of real shapes with support tables
   !> (stage 2b), is overlapping for `bodies_overlap` in both modes. It must also decide: at least
   !> half of the ellipsoid pairs closer than 0.9 of contact.
   subroutine test_early_stages(error)
      type(error_type), allocatable, intent(out) :: error
      integer, parameter :: nell = 3, nshape = 3
      real(wp), parameter :: axes(3, nell) = reshape([1.0_wp, 0.8_wp, 0.6_wp, 0.9_wp, 0.9_wp, 0.55_wp, &
                                                       1.2_wp, 0.5_wp, 0.5_wp], [3, nell])
      character(len=*), parameter :: files(nshape) = [character(len=48) :: &
         "/MA107-6-fine/MA107-6-fine-anm-00002.dat", "/MA107-6-fine/MA107-6-fine-anm-00017.dat", &
         "/MA111-7-coarse/MA111-7-coarse-anm-00009.dat"]
      character(len=:), allocatable :: dir
      type(contact_body_type) :: body(nell), real_body(nshape)
      type(sh_expansion_type) :: shape
      type(contact_params_type) :: par, cert
      type(rng_type) :: rng
      real(wp) :: rota(3, 3), rotb(3, 3), u(3), ca(3), cb(3), dstar, delta, sa, sb, lo, hi
      integer :: k, n, ia, ib, nfalse, nbeyond, ndeep, nproved, nreal
      logical :: early
      cert%certified = .true.
      do k = 1, nell
         call new_contact_body(body(k), ellipsoid_shape(axes(1, k), axes(2, k), axes(3, k), ell_order), error)
         if (allocated(error)) return
      end do
      call new_rng(rng, 17_i8, 4_i8)
      nfalse = 0
      nbeyond = 0
      ndeep = 0
      nproved = 0
      ca = 0.0_wp
      do n = 1, 6000
         ia = 1 + mod(n, nell)
         ib = 1 + mod(n / nell, nell)
         rota = random_rotation(rng)
         rotb = random_rotation(rng)
         u = [rng%normal(), rng%normal(), rng%normal()]
         u = u / norm2(u)
         dstar = 1.0_wp / sqrt(pw_function(rota, axes(:, ia), rotb, axes(:, ib), u))
         delta = 0.7_wp * rng%uniform() - 0.5_wp
         cb = ca + dstar * (1.0_wp + delta) * u
         early = overlap_early(body(ia), ca, rota, 1.0_wp, body(ib), cb, rotb, 1.0_wp, cert)
         if (early .and. delta > ell_band) nfalse = nfalse + 1
         if (early) then
            if (.not. (bodies_overlap(body(ia), ca, rota, 1.0_wp, body(ib), cb, rotb, 1.0_wp, cert) .and. &
                       bodies_overlap(body(ia), ca, rota, 1.0_wp, body(ib), cb, rotb, 1.0_wp, par))) &
               nbeyond = nbeyond + 1
         end if
         if (delta < -0.1_wp) then
            ndeep = ndeep + 1
            if (early) nproved = nproved + 1
         end if
      end do
      write (output_unit, '(4x,a,i0,a,i0,a,i0,a,i0)') "ellipsoids: 6000 pairs, closer than 0.9 of contact ", &
         ndeep, ", proved by the first stages ", nproved, ", false proofs ", nfalse, ", not confirmed ", nbeyond
      call check(error, nfalse + nbeyond, 0, "first-stage overlaps that are not overlaps (ellipsoids)")
      if (allocated(error)) return
      call check(error, 2 * nproved >= ndeep, "first stages proved only "//to_string(nproved)//" of " &
                 //to_string(ndeep)//" deep ellipsoid overlaps")
      if (allocated(error)) return
      ! real shapes with support tables: stage 2b takes part
      call shapes_dir(dir, error)
      if (allocated(error)) return
      do k = 1, nshape
         call load_shape_file(dir//trim(files(k)), shape, error)
         if (allocated(error)) return
         call new_contact_body(real_body(k), shape, error, nused=10)
         if (allocated(error)) return
      end do
      nbeyond = 0
      nreal = 0
      do n = 1, 3000
         ia = 1 + mod(n, nshape)
         ib = 1 + mod(n / nshape, nshape)
         rota = random_rotation(rng)
         rotb = random_rotation(rng)
         u = [rng%normal(), rng%normal(), rng%normal()]
         u = u / norm2(u)
         sa = 0.5_wp + rng%uniform()
         sb = 0.5_wp + rng%uniform()
         lo = sa * real_body(ia)%r_min + sb * real_body(ib)%r_min
         hi = sa * real_body(ia)%r_max + sb * real_body(ib)%r_max
         cb = (lo + (hi - lo) * rng%uniform()) * u
         if (overlap_early(real_body(ia), ca, rota, sa, real_body(ib), cb, rotb, sb, cert)) then
            nreal = nreal + 1
            if (.not. bodies_overlap(real_body(ia), ca, rota, sa, real_body(ib), cb, rotb, sb, cert)) &
               nbeyond = nbeyond + 1
         end if
      end do
      write (output_unit, '(4x,a,i0,a,i0)') "real shapes: 3000 pairs between the inscribed and bounding spheres, "// &
         "proved by the first stages ", nreal, ", not confirmed ", nbeyond
      call check(error, nbeyond, 0, "first-stage overlaps that the full test denies (real shapes)")
      if (allocated(error)) return
      call check(error, nreal > 300, "first stages proved only "//to_string(nreal)//" real-shape overlaps")
   end subroutine test_early_stages

   !> Dense reference: body-frame surface points of a shape on a (nt x 2nt) grid.
   subroutine dense_points(shape, nt, pts)
      type(sh_expansion_type), intent(in) :: shape
      integer, intent(in) :: nt
      real(wp), allocatable, intent(out) :: pts(:, :)
      integer :: i, j, k
      real(wp) :: th, ph, u(3)
      allocate (pts(3, 2 * nt * nt))
      k = 0
      do j = 1, 2 * nt
         ph = pi * (j - 0.37_wp) / nt
         do i = 1, nt
            th = pi * (i - 0.61_wp) / nt
            u = [sin(th) * cos(ph), sin(th) * sin(ph), cos(th)]
            k = k + 1
            pts(:, k) = shape%radius_dir(u) * u
         end do
      end do
   end subroutine dense_points

   !> Largest radial penetration (world units) of A's dense points into B.
   function dense_depth(pts, ca, rota, sa, shape_b, cb, rotb, sb) result(depth)
      real(wp), intent(in) :: pts(:, :), ca(3), rota(3, 3), sa, cb(3), rotb(3, 3), sb
      type(sh_expansion_type), intent(in) :: shape_b
      real(wp) :: depth, x(3), y(3), d
      integer :: k
      depth = 0.0_wp
      do k = 1, size(pts, 2)
         x = body_to_world(rota, ca, sa, pts(:, k))
         y = world_to_body(rotb, cb, sb, x)
         d = norm2(y)
         depth = max(depth, (shape_b%radius_dir(y) - d) * sb)
      end do
   end function dense_depth

   !> Distance test (`bodies_overlap` with a margin m: do the bodies come closer than m?) against
   !> exact distances. Spheres: D = |c_b - c_a| - r_a - r_b, set to m +- 1e-9 and at random
   !> around m; ellipsoid (order 24) and sphere: D = distance from the sphere's centre to the
   !> ellipsoid (its closest point by the Lagrange condition, solved to rounding) minus the
   !> radius. Every answer must be right outside the band [m - e, m + tol + e] (tol the certified
   !> gap tolerance, e the expansion's error); `overlap_early` may only prove pairs closer than m.
   subroutine test_margin_exact(error)
      type(error_type), allocatable, intent(out) :: error
      real(wp), parameter :: ax(3) = [1.0_wp, 0.7_wp, 0.45_wp]
      type(contact_body_type) :: ba, bb, be
      type(contact_params_type) :: par
      type(rng_type) :: rng
      real(wp) :: ra, rb, sa, sb, ca(3), cb(3), u(3), gap, rota(3, 3), rotb(3, 3), m, tol, dd, err, q(3)
      integer :: n, nbad, nearly, nband, ntest
      logical :: expect, got
      type(sh_expansion_type) :: shape
      call new_contact_body(ba, sphere_shape(1.0_wp), error)
      if (allocated(error)) return
      call new_contact_body(bb, sphere_shape(0.7_wp), error)
      if (allocated(error)) return
      par%certified = .true.
      call new_rng(rng, 17_i8, 3_i8)
      nbad = 0
      nearly = 0
      nband = 0
      ntest = 0
      do n = 1, 8000
         sa = 0.5_wp + rng%uniform()
         sb = 0.5_wp + 2.0_wp * rng%uniform()
         ra = sa * 1.0_wp
         rb = sb * 0.7_wp
         m = (ra + rb) * (0.005_wp + 0.3_wp * rng%uniform())
         tol = par%gap * min(2.0_wp * ra, 2.0_wp * rb)
         rota = random_rotation(rng)
         rotb = random_rotation(rng)
         u = [rng%normal(), rng%normal(), rng%normal()]
         u = u / norm2(u)
         select case (mod(n, 4))
         case (0)
            gap = m + 1.0e-9_wp
         case (1)
            gap = m - 1.0e-9_wp
         case default
            gap = m + 2.0_wp * m * (2.0_wp * rng%uniform() - 1.0_wp)
         end select
         ca = [10.0_wp, 10.0_wp, 10.0_wp] + [rng%uniform(), rng%uniform(), rng%uniform()]
         cb = ca + (ra + rb + gap) * u
         gap = norm2(cb - ca) - ra - rb
         got = bodies_overlap(ba, ca, rota, sa, bb, cb, rotb, sb, par, margin=m)
         if (gap >= m .and. overlap_early(ba, ca, rota, sa, bb, cb, rotb, sb, par, margin=m)) nearly = nearly + 1
         if (gap >= m .and. gap <= m + tol + 1.0e-12_wp) then
            nband = nband + 1
            cycle
         end if
         ntest = ntest + 1
         if (got .neqv. gap < m) nbad = nbad + 1
      end do
      write (output_unit, '(a,i0,a,i0,a,i0)') "    spheres: tested ", ntest, ", in [m, m + tol] ", nband, &
         ", wrong ", nbad
      call check(error, nbad + nearly, 0, "wrong sphere decisions with a margin")
      if (allocated(error)) return
      ! ellipsoid (A) and sphere (B)
      shape = ellipsoid_shape(ax(1), ax(2), ax(3), ell_order)
      err = ellipsoid_error(shape, ax)
      call new_contact_body(be, shape, error)
      if (allocated(error)) return
      nbad = 0
      nband = 0
      ntest = 0
      ca = 0.0_wp
      do n = 1, 6000
         rota = random_rotation(rng)
         rotb = random_rotation(rng)
         sb = 0.1_wp + 0.6_wp * rng%uniform()
         rb = 0.7_wp * sb
         m = 0.01_wp + 0.25_wp * rng%uniform()
         u = [rng%normal(), rng%normal(), rng%normal()]
         u = u / norm2(u)
         ! centre of B at a random distance beyond the ellipsoid's surface point along u
         q = ellipsoid_radius(ax(1), ax(2), ax(3), matmul(u, rota)) * u
         cb = q + (rb + m * 2.0_wp * rng%uniform() + 0.3_wp * m * rng%normal()) * u
         dd = ellipsoid_distance(ax, matmul(cb - ca, rota)) - rb
         tol = par%gap * min(2.0_wp * ax(1), 2.0_wp * rb)
         got = bodies_overlap(be, ca, rota, 1.0_wp, bb, cb, rotb, sb, par, margin=m)
         if (dd >= m - err - 1.0e-9_wp .and. dd <= m + tol + err + 1.0e-9_wp) then
            nband = nband + 1
            cycle
         end if
         if (dd >= m .and. overlap_early(be, ca, rota, 1.0_wp, bb, cb, rotb, sb, par, margin=m)) nearly = nearly + 1
         ntest = ntest + 1
         if (got .neqv. dd < m) nbad = nbad + 1
      end do
      write (output_unit, '(a,es9.2,a,i0,a,i0,a,i0)') "    ellipsoid-sphere (expansion error ", err, "): tested ", &
         ntest, ", in the band ", nband, ", wrong ", nbad
      call check(error, ntest >= 5000, "fewer than 5000 ellipsoid-sphere pairs outside the band")
      if (allocated(error)) return
      call check(error, nbad + nearly, 0, "wrong ellipsoid-sphere decisions with a margin")
   end subroutine test_margin_exact

   !> Distance from the point q (ellipsoid frame, outside or inside) to the ellipsoid surface
   !> x^2/a^2 + y^2/b^2 + z^2/c^2 = 1: for q outside, the closest point is a_i^2 q_i/(a_i^2 + t)
   !> with t > 0 the root of sum (a_i q_i/(a_i^2 + t))^2 = 1 (bisection to rounding); negative
   !> (minus a lower bound of the depth) for q inside.
   pure function ellipsoid_distance(a, q) result(d)
      real(wp), intent(in) :: a(3), q(3)
      real(wp) :: d, lo, hi, t, x(3)
      integer :: it
      if (sum((q / a)**2) <= 1.0_wp) then
         d = -1.0_wp
         return
      end if
      lo = 0.0_wp
      hi = maxval(a) * norm2(q) + maxval(a)**2
      do it = 1, 200
         t = 0.5_wp * (lo + hi)
         if (sum((a * q / (a**2 + t))**2) > 1.0_wp) then
            lo = t
         else
            hi = t
         end if
         if (hi - lo <= 1.0e-15_wp * hi) exit
      end do
      t = 0.5_wp * (lo + hi)
      x = a**2 * q / (a**2 + t)
      d = norm2(q - x)
   end function ellipsoid_distance

   !> Distance test on real shapes (MA111-7-coarse, order 14) near the margin, against dense
   !> surface points of both bodies (60 x 120 directions each): their closest pair of points gives
   !> an upper bound D_s of the distance, and D_s - h_a - h_b a lower bound (h the largest distance
   !> from a surface point to the nearest sample, bounded with the certified Lipschitz constant).
   !> "No" must never come with D_s < m; "yes" never with D_s - h_a - h_b > m + tol.
   subroutine test_margin_real(error)
      type(error_type), allocatable, intent(out) :: error
      integer, parameter :: nshape = 3, npair = 90, nt = 60
      character(len=5), parameter :: ids(nshape) = ["00002", "00035", "00061"]
      character(len=:), allocatable :: dir
      type(sh_expansion_type) :: shape
      type(contact_body_type) :: body(nshape)
      type(contact_params_type) :: par
      type(rng_type) :: rng
      type(real_pts_type), allocatable :: pts(:)
      real(wp), allocatable :: xa(:, :), xb(:, :)
      real(wp) :: rota(3, 3), rotb(3, 3), u(3), ca(3), cb(3), lo, hi, mid, m, ds, h(nshape), lmin, tol, d2
      integer :: k, n, ia, ib, it, i, j, na, nb, nyes, nno, nwrong, nband, nearly
      logical :: got
      integer(i8) :: t0, t1, rate
      real(wp) :: tsum
      call shapes_dir(dir, error)
      if (allocated(error)) return
      allocate (pts(nshape))
      do k = 1, nshape
         call load_shape_file(dir//"/MA111-7-coarse/MA111-7-coarse-anm-"//ids(k)//".dat", shape, error)
         if (allocated(error)) return
         call new_contact_body(body(k), shape, error, nused=14)
         if (allocated(error)) return
         call dense_points(body(k)%shape, nt, pts(k)%p)
         ! every direction is within pi/nt of a sample direction (grid cells of pi/nt): the
         ! surface moves by at most r_max pi/nt sideways and lipschitz pi/nt radially
         h(k) = (body(k)%r_max + body(k)%lipschitz) * pi / nt
      end do
      par%certified = .true.
      call new_rng(rng, 23_i8, 5_i8)
      nyes = 0
      nno = 0
      nwrong = 0
      nband = 0
      nearly = 0
      tsum = 0.0_wp
      ca = 0.0_wp
      do n = 1, npair
         ia = 1 + mod(n, nshape)
         ib = 1 + mod(n / nshape, nshape)
         rota = random_rotation(rng)
         rotb = random_rotation(rng)
         u = [rng%normal(), rng%normal(), rng%normal()]
         u = u / norm2(u)
         lmin = min(maxval(body(ia)%box_hi - body(ia)%box_lo), maxval(body(ib)%box_hi - body(ib)%box_lo))
         m = lmin * (0.01_wp + 0.06_wp * rng%uniform())
         tol = par%gap * lmin
         ! contact distance along u (certified test, bisection), then up to 2 m further
         lo = body(ia)%r_min + body(ib)%r_min
         hi = body(ia)%r_max + body(ib)%r_max
         do it = 1, 40
            mid = 0.5_wp * (lo + hi)
            if (bodies_overlap(body(ia), ca, rota, 1.0_wp, body(ib), mid * u, rotb, 1.0_wp, par)) then
               lo = mid
            else
               hi = mid
            end if
         end do
         cb = (hi + 2.0_wp * m * rng%uniform()) * u
         call system_clock(t0, rate)
         got = bodies_overlap(body(ia), ca, rota, 1.0_wp, body(ib), cb, rotb, 1.0_wp, par, margin=m)
         call system_clock(t1)
         tsum = tsum + real(t1 - t0, wp) / real(rate, wp)
         ! dense points near the other body
         xa = world_points(pts(ia)%p, rota, ca)
         xb = world_points(pts(ib)%p, rotb, cb)
         xa = pack_near(xa, cb, body(ib)%r_max + m + h(ia))
         xb = pack_near(xb, ca, body(ia)%r_max + m + h(ib))
         na = size(xa, 2)
         nb = size(xb, 2)
         d2 = huge(1.0_wp)
         do j = 1, nb
            do i = 1, na
               d2 = min(d2, (xa(1, i) - xb(1, j))**2 + (xa(2, i) - xb(2, j))**2 + (xa(3, i) - xb(3, j))**2)
            end do
         end do
         ds = sqrt(d2)
         ! the first stages (with a margin: the local descent of near_points too) prove only pairs
         ! closer than m itself
         if (overlap_early(body(ia), ca, rota, 1.0_wp, body(ib), cb, rotb, 1.0_wp, par, margin=m)) then
            nearly = nearly + 1
            if (ds - h(ia) - h(ib) > m) nwrong = nwrong + 1
         end if
         if (got) then
            nyes = nyes + 1
            if (ds - h(ia) - h(ib) > m + tol) nwrong = nwrong + 1
         else
            nno = nno + 1
            if (ds < m) nwrong = nwrong + 1
         end if
         if (ds >= m .and. ds - h(ia) - h(ib) <= m + tol) nband = nband + 1
      end do
      write (output_unit, '(a,i0,a,i0,a,i0,a,i0,a,i0,a,i0,a,f8.1,a)') "    ", npair, " pairs: closer than m ", nyes, &
         " (", nearly, " by the first stages), apart ", nno, ", wrong ", nwrong, ", undecidable by the samples ", &
         nband, ", mean test ", 1.0e6_wp * tsum / npair, " us"
      call check(error, nwrong, 0, "distance decisions contradicting the dense points")
      if (allocated(error)) return
      call check(error, nyes >= npair / 5 .and. nno >= npair / 5, "expected both answers among the pairs")
   contains
      pure function world_points(p, rot, c) result(x)
         real(wp), intent(in) :: p(:, :), rot(3, 3), c(3)
         real(wp), allocatable :: x(:, :)
         integer :: q
         allocate (x(3, size(p, 2)))
         do q = 1, size(p, 2)
            x(:, q) = c + matmul(rot, p(:, q))
         end do
      end function world_points
      pure function pack_near(x, c, r) result(y)
         real(wp), intent(in) :: x(:, :), c(3), r
         real(wp), allocatable :: y(:, :)
         logical :: keep(size(x, 2))
         integer :: q, nk
         do q = 1, size(x, 2)
            keep(q) = norm2(x(:, q) - c) <= r
         end do
         nk = count(keep)
         allocate (y(3, nk))
         nk = 0
         do q = 1, size(x, 2)
            if (.not. keep(q)) cycle
            nk = nk + 1
            y(:, nk) = x(:, q)
         end do
      end function pack_near
   end subroutine test_margin_real

   !> Walls with a margin m: an ellipsoid (order 24) in a box keeps m from every wall exactly when
   !> its exact extent along each axis (sqrt(sum_j R_ij^2 a_j^2)) does. "Keeps m" is never
   !> answered for a gap below m; "too close" may be answered for gaps up to m + 3e-3 (patches
   !> still undecided at the wall test's finest level are reported as touching, as without a
   !> margin: `test_walls`).
   subroutine test_margin_walls(error)
      type(error_type), allocatable, intent(out) :: error
      real(wp), parameter :: ax(3) = [1.0_wp, 0.7_wp, 0.45_wp], box(3) = [5.0_wp, 4.0_wp, 6.0_wp]
      type(contact_body_type) :: be
      type(sh_expansion_type) :: shape
      type(rng_type) :: rng
      real(wp) :: rot(3, 3), c(3), ext(3), m, err, gap
      integer :: n, k, nbad, ntest, nfp
      logical :: expect
      shape = ellipsoid_shape(ax(1), ax(2), ax(3), ell_order)
      err = ellipsoid_error(shape, ax)
      call new_contact_body(be, shape, error)
      if (allocated(error)) return
      call new_rng(rng, 29_i8, 1_i8)
      nbad = 0
      nfp = 0
      ntest = 0
      do n = 1, 4000
         rot = random_rotation(rng)
         m = 0.05_wp + 0.3_wp * rng%uniform()
         do k = 1, 3
            ext(k) = sqrt(sum(rot(k, :)**2 * ax**2))
         end do
         c = [(ext(k) + m + 0.2_wp * (2.0_wp * rng%uniform() - 1.0_wp) + rng%uniform() * (box(k) - 2.0_wp * (ext(k) &
              + m)), k=1, 3)]
         gap = minval([(min(c(k) - ext(k), box(k) - c(k) - ext(k)), k=1, 3)])
         if (abs(gap - m) <= 2.0_wp * err) cycle
         expect = gap < m
         ntest = ntest + 1
         if (body_crosses_walls(be, c, rot, 1.0_wp, box, margin=m)) then
            if (.not. expect) then
               nfp = nfp + 1
               if (gap - m > 3.0e-3_wp) nbad = nbad + 1
            end if
         else
            if (expect) nbad = nbad + 1
         end if
      end do
      write (output_unit, '(a,i0,a,i0,a,i0)') "    tested ", ntest, ", conservative 'too close' within 3e-3 of m ", &
         nfp, ", wrong ", nbad
      call check(error, ntest >= 2000, "fewer than 2000 wall cases outside the band")
      if (allocated(error)) return
      call check(error, nbad, 0, "wrong wall decisions with a margin")
   end subroutine test_margin_walls

   subroutine test_real_shapes(error)
      type(error_type), allocatable, intent(out) :: error
      integer, parameter :: nshape = 4, npair = 160, nnbox = 4
      character(len=5), parameter :: ids(nshape) = ["00002", "00009", "00035", "00061"]
      integer, parameter :: nboxes(nnbox) = [32, 64, 128, 256]
      character(len=:), allocatable :: dir
      type(sh_expansion_type) :: shape(nshape)
      type(contact_body_type) :: body(nshape)
      type(contact_params_type) :: par, cert
      type(rng_type) :: rng
      type(real_pts_type), allocatable :: pts(:)
      real(wp) :: rota(3, 3), rotb(3, 3), u(3), ca(3), cb(3), lo, hi, mid, depth, lmin, dref
      integer :: k, n, ia, ib, it, ib2, nover, fneg(nnbox), fpos(nnbox), fneg_big(nnbox), fneg_cert, fpos_cert
      logical :: ref, got
      call shapes_dir(dir, error)
      if (allocated(error)) return
      allocate (pts(nshape))
      do k = 1, nshape
         call load_shape_file(dir//"/MA111-7-coarse/MA111-7-coarse-anm-"//ids(k)//".dat", shape(k), error)
         if (allocated(error)) return
         call new_contact_body(body(k), shape(k), error, nused=14)
         if (allocated(error)) return
         call dense_points(body(k)%shape, 120, pts(k)%p)
      end do
      cert%certified = .true.
      call new_rng(rng, 21_i8, 4_i8)
      fneg = 0
      fpos = 0
      fneg_big = 0
      fneg_cert = 0
      fpos_cert = 0
      nover = 0
      ca = [0.0_wp, 0.0_wp, 0.0_wp]
      do n = 1, npair
         ia = 1 + mod(n, nshape)
         ib = 1 + mod(n / nshape, nshape)
         rota = random_rotation(rng)
         rotb = random_rotation(rng)
         u = [rng%normal(), rng%normal(), rng%normal()]
         u = u / norm2(u)
         ! contact distance along u by bisection on D_overlap at N_box = 256, then a random offset
         lo = body(ia)%r_min + body(ib)%r_min
         hi = body(ia)%r_max + body(ib)%r_max
         do it = 1, 22
            mid = 0.5_wp * (lo + hi)
            if (overlap_depth(body(ia), ca, rota, 1.0_wp, body(ib), mid * u, rotb, 1.0_wp, 256) > 0.0_wp) then
               lo = mid
            else
               hi = mid
            end if
         end do
         cb = hi * (1.0_wp + 0.02_wp * (2.0_wp * rng%uniform() - 1.0_wp)) * u
         dref = max(dense_depth(pts(ia)%p, ca, rota, 1.0_wp, body(ib)%shape, cb, rotb, 1.0_wp), &
                    dense_depth(pts(ib)%p, cb, rotb, 1.0_wp, body(ia)%shape, ca, rota, 1.0_wp))
         ref = dref > 0.0_wp
         if (ref) nover = nover + 1
         lmin = min(maxval(body(ia)%box_hi - body(ia)%box_lo), maxval(body(ib)%box_hi - body(ib)%box_lo))
         do ib2 = 1, nnbox
            par%nbox = nboxes(ib2)
            got = bodies_overlap(body(ia), ca, rota, 1.0_wp, body(ib), cb, rotb, 1.0_wp, par)
            if (ref .and. .not. got) then
               fneg(ib2) = fneg(ib2) + 1
               if (dref >= 0.005_wp * lmin) fneg_big(ib2) = fneg_big(ib2) + 1
            end if
            if (got .and. .not. ref) fpos(ib2) = fpos(ib2) + 1
         end do
         got = bodies_overlap(body(ia), ca, rota, 1.0_wp, body(ib), cb, rotb, 1.0_wp, cert)
         if (ref .and. .not. got) fneg_cert = fneg_cert + 1
         if (got .and. .not. ref) fpos_cert = fpos_cert + 1
         depth = overlap_depth(body(ia), ca, rota, 1.0_wp, body(ib), cb, rotb, 1.0_wp, 256)
         if (depth > dref * 1.5_wp + 1.0e-3_wp * lmin) then
            call fatal_error(error, "D_overlap "//to_string(depth)//" exceeds the dense reference " &
                             //to_string(dref))
            return
         end if
      end do
      write (output_unit, '(a,i0,a,i0,a)') "    ", npair, " pairs, ", nover, " overlapping (dense reference)"
      do ib2 = 1, nnbox
         write (output_unit, '(a,i4,a,i3,a,i3,a,i3)') "    N_box ", nboxes(ib2), ": false negatives ", fneg(ib2), &
            " (depth >= 0.5% L: ", fneg_big(ib2), "), false positives ", fpos(ib2)
      end do
      write (output_unit, '(a,i3,a,i3)') "    certified: false negatives ", fneg_cert, ", false positives ", fpos_cert
      call check(error, nover > npair / 4 .and. nover < 3 * npair / 4, "expected about half the pairs to overlap")
      if (allocated(error)) return
      call check(error, fneg_big(3), 0, "false negatives >= 0.5% L at the default N_box")
      if (allocated(error)) return
      call check(error, fneg_cert, 0, "certified false negatives")
   end subroutine test_real_shapes

   subroutine test_walls(error)
      type(error_type), allocatable, intent(out) :: error
      real(wp), parameter :: ax(3) = [1.0_wp, 0.7_wp, 0.5_wp]
      type(contact_body_type) :: body, sph
      type(rng_type) :: rng
      real(wp) :: rot(3, 3), c(3), h(3), box(3), err, margin, s
      integer :: n, k, nwrong, nsph, nconservative
      logical :: got
      real(wp), parameter :: wall_band = 0.005_wp
      real(wp) :: gmax
      type(sh_expansion_type) :: shape
      shape = ellipsoid_shape(ax(1), ax(2), ax(3), ell_order)
      err = ellipsoid_error(shape, ax)
      call new_contact_body(body, shape, error)
      if (allocated(error)) return
      call new_contact_body(sph, sphere_shape(1.0_wp), error)
      if (allocated(error)) return
      call new_rng(rng, 8_i8, 3_i8)
      box = [5.0_wp, 6.0_wp, 7.0_wp]
      nwrong = 0
      nsph = 0
      nconservative = 0
      gmax = 0.0_wp
      do n = 1, 20000
         rot = random_rotation(rng)
         s = 0.5_wp + rng%uniform()
         c = box * [rng%uniform(), rng%uniform(), rng%uniform()]
         do k = 1, 3
            h(k) = s * sqrt(sum((rot(k, :) * ax)**2))
         end do
         margin = minval(min(c - h, box - c - h))
         got = body_crosses_walls(body, c, rot, s, box)
         ! crossing by more than the expansion error must be seen ("false" is guaranteed)
         if (margin < -2.0_wp * s * err - 1.0e-9_wp .and. .not. got) nwrong = nwrong + 1
         ! clear of the walls by more than the band must be "false"
         if (margin > wall_band * s .and. got) nwrong = nwrong + 1
         if (got .and. margin > 2.0_wp * s * err) nconservative = nconservative + 1
         if (got) gmax = max(gmax, margin / s)
         margin = minval(min(c - s, box - c - s))
         if (abs(margin) > 1.0e-9_wp) then
            if (body_crosses_walls(sph, c, rot, s, box) .neqv. (margin <= 0.0_wp)) nsph = nsph + 1
         end if
      end do
      write (output_unit, '(a,i0,a,es9.2,a)') "    walls: ", nconservative, &
         " conservative 'touching' answers; largest gap called touching ", gmax, " x scale"
      call check(error, nwrong + nsph, 0, "wall decisions (ellipsoid "//to_string(nwrong)//", sphere " &
                 //to_string(nsph)//")")
   end subroutine test_walls

   subroutine test_newton_raphson(error)
      type(error_type), allocatable, intent(out) :: error
      real(wp), parameter :: ax(3) = [1.0_wp, 0.8_wp, 0.6_wp]
      type(contact_body_type) :: ell, sa, sb
      type(contact_params_type) :: nr
      type(rng_type) :: rng
      real(wp) :: rota(3, 3), rotb(3, 3), u(3), cb(3), f1, dstar, delta, gap
      integer :: n, fp, fnn, novl, nsph
      logical :: expect, got
      nr%method = contact_method%newton_raphson
      call new_contact_body(sa, sphere_shape(1.0_wp), error)
      if (allocated(error)) return
      call new_contact_body(sb, sphere_shape(0.5_wp), error)
      if (allocated(error)) return
      call new_contact_body(ell, ellipsoid_shape(ax(1), ax(2), ax(3), ell_order), error)
      if (allocated(error)) return
      call new_rng(rng, 9_i8, 5_i8)
      nsph = 0
      do n = 1, 2000
         rota = random_rotation(rng)
         u = [rng%normal(), rng%normal(), rng%normal()]
         u = u / norm2(u)
         gap = merge(1.0e-9_wp, -1.0e-9_wp, mod(n, 2) == 0)
         if (bodies_overlap(sa, [0.0_wp, 0.0_wp, 0.0_wp], rota, 1.0_wp, sb, (1.5_wp + gap) * u, rota, 1.0_wp, nr) &
             .neqv. gap < 0.0_wp) nsph = nsph + 1
      end do
      fp = 0
      fnn = 0
      novl = 0
      do n = 1, 300
         rota = random_rotation(rng)
         rotb = random_rotation(rng)
         u = [rng%normal(), rng%normal(), rng%normal()]
         u = u / norm2(u)
         f1 = pw_function(rota, ax, rotb, ax, u)
         dstar = 1.0_wp / sqrt(f1)
         delta = sign(0.05_wp + 0.15_wp * rng%uniform(), rng%uniform() - 0.5_wp)
         cb = dstar * (1.0_wp + delta) * u
         expect = delta < 0.0_wp
         if (expect) novl = novl + 1
         got = bodies_overlap(ell, [0.0_wp, 0.0_wp, 0.0_wp], rota, 1.0_wp, ell, cb, rotb, 1.0_wp, nr)
         if (got .and. .not. expect) fp = fp + 1
         if (expect .and. .not. got) fnn = fnn + 1
      end do
      write (output_unit, '(a,i0,a,i0,a,i0,a,i0)') "    NR: sphere errors ", nsph, "; ellipsoids 5-20% from contact: ", &
         novl, " overlapping, missed ", fnn, ", false positives ", fp
      call check(error, nsph + fp, 0, "Newton-Raphson wrong on spheres or false positive")
      if (allocated(error)) return
      call check(error, fnn <= novl / 5, "Newton-Raphson misses more than 20% of clear overlaps")
   end subroutine test_newton_raphson
   !> The thesis' reading of N_box (anm_contact_studies): N_box points over the angular range of the
   !> surface inside the EOB. Two unit spheres 1.998 apart overlap by exactly 0.002 along the line of
   !> centres: along z (a node of the N_ext scan, so the EOB holds the tip) the scan finds 0.002;
   !> along x the N_ext extent box clips the tip and the scan finds at most the analytic depth of the
   !> clipped cap (the thesis' method misses overlaps outside its extent boxes). Apart, the depth is 0. Two ellipsoids at 0.998
   !> of their contact distance: the thesis' reading at N_box = 301 finds nearly the depth the
   !> engine's reading finds at 1024 (both sample the same surfaces inside the same EOB).
   subroutine test_thesis_nbox(error)
      type(error_type), allocatable, intent(out) :: error
      type(contact_body_type) :: sph, ell
      type(rng_type) :: rng
      real(wp) :: eye(3, 3), ra(3, 3), rb(3, 3), d, lo, hi, mid, d_thesis, d_engine, zero(3), ex(3), c, dmax
      integer :: i, it
      call new_contact_body(sph, sphere_shape(1.0_wp), error)
      if (allocated(error)) return
      eye = 0.0_wp
      do i = 1, 3
         eye(i, i) = 1.0_wp
      end do
      zero = 0.0_wp
      ex = [1.0_wp, 0.0_wp, 0.0_wp]
      ! along x the N_ext = 40 extent box clips the tip (no theta node at pi/2: x <= c = cos(pi/78)),
      ! so the deepest point inside the EOB has x = c: D <= 1 - sqrt((1.998 - c)^2 + 1 - c^2) < 0.002
      c = cos(pi / 78.0_wp)
      dmax = 1.0_wp - sqrt((1.998_wp - c)**2 + 1.0_wp - c**2)
      d = thesis_overlap_depth(sph, zero, eye, sph, 1.998_wp * ex, eye, 41)
      print '(a,2es12.5)', "        spheres along x, N_box 41: D_overlap, bound from the clipped EOB: ", d, dmax
      call check(error, d <= dmax + 1.0e-12_wp .and. d >= 0.5_wp * dmax, "spheres along x: D_overlap " &
                 //to_string(d)//" not within [0.5, 1] x "//to_string(dmax))
      if (allocated(error)) return
      d = thesis_overlap_depth(sph, zero, eye, sph, [0.0_wp, 0.0_wp, 1.998_wp], eye, 40)
      call check(error, abs(d - 0.002_wp) < 1.0e-9_wp, "spheres along z: D_overlap "//to_string(d)//" /= 0.002")
      if (allocated(error)) return
      d = thesis_overlap_depth(sph, zero, eye, sph, 2.001_wp * ex, eye, 41)
      call check(error, d == 0.0_wp, "spheres apart: D_overlap "//to_string(d)//" /= 0")
      if (allocated(error)) return
      call new_contact_body(ell, ellipsoid_shape(3.0_wp, 2.0_wp, 1.0_wp, 12), error)
      if (allocated(error)) return
      call new_rng(rng, 11_i8, 1_i8)
      ra = random_rotation(rng)
      rb = random_rotation(rng)
      lo = 2.0_wp * ell%r_min
      hi = 2.0_wp * ell%r_max
      do it = 1, 40
         mid = 0.5_wp * (lo + hi)
         if (overlap_depth(ell, zero, ra, 1.0_wp, ell, mid * ex, rb, 1.0_wp, 1024) > 0.0_wp) then
            lo = mid
         else
            hi = mid
         end if
      end do
      d_engine = overlap_depth(ell, zero, ra, 1.0_wp, ell, 0.99_wp * lo * ex, rb, 1.0_wp, 1024)
      d_thesis = thesis_overlap_depth(ell, zero, ra, ell, 0.99_wp * lo * ex, rb, 301)
      print '(a,2es12.5)', "        ellipsoids at 0.99 contact: D_overlap thesis (301), engine (1024): ", d_thesis, &
         d_engine
      call check(error, d_engine > 0.0_wp .and. abs(d_thesis - d_engine) <= 0.05_wp * d_engine, &
                 "ellipsoids: the thesis' reading differs from the engine's by more than 5 %")
   end subroutine test_thesis_nbox
end module test_contact
