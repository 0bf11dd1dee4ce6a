!> The outer radius R_t(u) of a shell of thickness t along the directions u of a grid
!> (`offset_grid`, the production path) or along one direction (`offset_radius`, the reference).
!>
!> R_t(u) = max{rho : dist(rho u, particle) <= t} = max over surface points x of
!> g_u(x) = u . x + sqrt(t^2 - |x - (u . x) u|^2): the stationary points of g_u are exactly the
!> roots of the thesis' Eq 2.1, r(theta', phi') + t n(theta', phi') = (r(theta, phi) + beta) u, so
!> R_t is the largest valid Newton root, and every surface sample gives a lower bound.
!>
!> `offset_grid`: sampled lower bounds and starts (cells of surface samples spread over the
!> directions their offset points cover), Newton from the best sample (first step from tabulated
!> derivatives, then exact evaluations in batches), acceptance by the local conditions and the
!> sampled bound, continuation from neighbours' feet across creases, the definition as fallback.
!>
!> `offset_radius`: Newton from the sample best aligned with u, validated by a distance search
!> over the surface (`surface_distance`), else the definition itself by safeguarded
!> Newton/bisection on rho (slow; used by the tests as the reference).
!>
!> Usage:
!>     call offset_grid(surf, t, rt, counts)               ! R_t at every node of surf%grid
!>     call offset_radius(surf, theta, phi, t, rt, used_fallback)
module anm_shells_offset
   use, intrinsic :: iso_c_binding, only: c_bool
   use anm_core_kinds, only: wp, pi, two_pi
   use anm_shells_surface, only: shell_surface_type, eval_surface, eval_surface_many, surface_frame, surface_frame_trig, &
      & surface_distance, cross3, node_geometry, column_geometry
   implicit none
   private

   public :: offset_radius, offset_newton, offset_grid, offset_counts_type

   !> Relative tolerance on distances (of t) when validating a Newton root.
   real(wp), parameter :: distance_tol = 1.0e-7_wp
   !> Newton step (radians) below which the root is finished by a second-order Taylor step
   !> (the error of R_t is then of the order of the cube of this step times the third derivatives).
   real(wp), parameter :: finish_step = 3.0e-4_wp
   !> Tolerance (relative to rmax + t) below the sampled lower bound at which a root is rejected.
   real(wp), parameter :: bound_tol = 1.0e-9_wp
   !> Feet of grid-adjacent directions farther apart than this many hmax mark a crease.
   real(wp), parameter :: jump_factor = 2.0_wp
   !> Largest number of continuation passes over the grid.
   integer, parameter :: max_passes = 30
   !> Largest number of Newton iterations per start.
   integer, parameter :: max_newton = 30
   !> Newton gives up where |sin(theta')| falls below this (the poles of the parametrisation).
   real(wp), parameter :: pole_sin = 1.0e-6_wp
   !> Slots of the first Newton pass (directions in flight; its working arrays, some 150 kB on the
   !> stack).
   integer, parameter :: pool = 1024
   !> Directions per call of `newton_lanes` (four AVX-512 registers per quantity).
   integer, parameter :: step_lanes = 32

   !> States of a Newton iteration (enumerator).
   type :: newton_state_enum
      integer :: running = 0
      integer :: converged = 1
      integer :: failed = 2
   end type newton_state_enum
   !> Newton states.
   type(newton_state_enum), parameter :: newton_state = newton_state_enum()

   !> How the directions of one grid were solved.
   type :: offset_counts_type
      !> Directions solved by Newton (Eq 2.1), from the sampled start or by continuation.
      integer :: newton = 0
      !> Directions whose root came from a neighbour's foot (continuation across creases).
      integer :: continued = 0
      !> Directions that needed the distance-definition fallback.
      integer :: fallback = 0
      !> Exact evaluations of the particle expansion spent in Newton iterations.
      integer :: evaluations = 0
   end type offset_counts_type

contains

   !> Outer radius of the shell of thickness t along the unit direction u = (theta, phi).
   pure subroutine offset_radius(surf, theta, phi, t, rt, used_fallback)
      !> Surface data of the particle.
      type(shell_surface_type), intent(in) :: surf
      !> Direction (theta in (0, pi)).
      real(wp), intent(in) :: theta, phi
      !> Thickness (> 0).
      real(wp), intent(in) :: t
      !> R_t along the direction.
      real(wp), intent(out) :: rt
      !> True when the Newton construction had no valid root here.
      logical, intent(out) :: used_fallback
      real(wp) :: u(3), ts, ps, rho, dist, thc, phc, f(6), xs(3)
      logical :: ok

      u = [sin(theta) * cos(phi), sin(theta) * sin(phi), cos(theta)]
      call start_point(surf, u, t, ts, ps)
      call offset_newton(surf, theta, phi, t, ts, ps, rho, ok)
      if (ok) then
         call eval_surface(surf, ts, ps, f)
         xs = f(1) * [sin(ts) * cos(ps), sin(ts) * sin(ps), cos(ts)]
         call surface_distance(surf, rho * u, t, dist, thc, phc, known=xs)
         ok = dist >= t * (1.0_wp - distance_tol)
      end if
      used_fallback = .not. ok
      if (ok) then
         rt = rho
      else
         call definition_radius(surf, u, t, rt)
      end if
   end subroutine offset_radius

   !> R_t at every node of the surface's own grid.
   !>
   !> 1. Sampled bound and start: R_t(u) = max over surface points x of
   !>    g_u(x) = u . x + sqrt(t^2 - |x - (u . x) u|^2) (the farthest point of the ray within t of x),
   !>    so every sample gives a lower bound. Each sample's value is spread to the directions near
   !>    its offset direction (x_s + t n_s) / |x_s + t n_s| (within the angle its grid neighbours'
   !>    offset directions span, plus one spacing); per direction the best sample is the start and
   !>    its g the lower bound m(u). Where no sample is within t of the ray (thin shells), the start
   !>    is the sample whose offset direction is best aligned with u.
   !> 2. Newton (Eq 2.1) from the start: the first step uses the tabulated derivatives, later steps
   !>    the exact expansion; finished by a second-order Taylor step once the step is below
   !>    `finish_step`. Accepted when beta > 0, u . n > 0, the foot is a strict local minimum of the
   !>    distance (1 - t kappa_i > 0) and R >= m(u) (a root below a sampled point is the wrong sheet).
   !> 3. Continuation: where the feet of adjacent directions jump (a crease: two sheets of the offset
   !>    surface) or Newton failed, Newton is restarted from the neighbours' feet and the largest
   !>    accepted root kept (R_t is the maximum over the sheets), pass after pass until nothing changes.
   !> 4. Directions still unsolved use the definition (`definition_radius`).
   pure subroutine offset_grid(surf, t, rt, counts)
      !> Surface data of the particle (its grid is the direction grid).
      type(shell_surface_type), intent(in) :: surf
      !> Thickness (> 0).
      real(wp), intent(in) :: t
      !> R_t(i, j) at node (i, j).
      real(wp), intent(out) :: rt(:, :)
      !> How the directions were solved.
      type(offset_counts_type), intent(out) :: counts
      real(wp), allocatable :: lower(:, :), foot(:, :, :), fx(:, :, :)
      integer, allocatable :: start(:, :)
      ! (one-byte flags and one start index per node: less fresh memory per shell)
      logical(c_bool), allocatable :: solved(:, :), from_nb(:, :), changed(:, :), dirty(:, :)
      real(wp) :: rho, jump2, tol, u(3), e1(3), e2(3), th, ph, xf(3)
      integer :: nt, np, i, j, k, ii, jj, pass, nev
      logical :: ok, any_change

      nt = surf%grid%sphere%ntheta
      np = surf%grid%sphere%nphi
      allocate (lower(nt, np), start(nt, np))
      call sampled_starts(surf, t, lower, start)
      ! (allocated after the sampled bounds, whose working arrays they may reuse)
      allocate (foot(2, nt, np), fx(3, nt, np), solved(nt, np), from_nb(nt, np), changed(nt, np), dirty(nt, np))
      tol = bound_tol * (surf%rmax + t)
      jump2 = (jump_factor * surf%hmax)**2
      from_nb = .false.
      call first_pass(surf, t, start, lower, tol, rt, solved, foot, fx, counts%evaluations)
      ! continuation across creases and from solved neighbours
      dirty = .true.
      do pass = 1, max_passes
         any_change = .false.
         changed = .false.
         do j = 1, np
            do i = 1, nt
               if (.not. dirty(i, j)) cycle
               do k = 1, 4
                  call neighbour(i, j, k, nt, np, ii, jj)
                  if (.not. solved(ii, jj)) cycle
                  if (solved(i, j)) then
                     if (sum((fx(:, i, j) - fx(:, ii, jj))**2) <= jump2) cycle
                  end if
                  call node_frame(surf, i, j, u, e1, e2)
                  th = foot(1, ii, jj)
                  ph = foot(2, ii, jj)
                  call foot_newton(surf, u, e1, e2, t, surf%r(i, j), th, ph, rho, xf, ok, nev)
                  counts%evaluations = counts%evaluations + nev
                  if (.not. (ok .and. rho >= lower(i, j) - tol)) cycle
                  if (solved(i, j)) then
                     if (rho <= rt(i, j) + tol) cycle
                  end if
                  rt(i, j) = rho
                  solved(i, j) = .true.
                  from_nb(i, j) = .true.
                  foot(:, i, j) = [th, ph]
                  fx(:, i, j) = xf
                  changed(i, j) = .true.
                  any_change = .true.
               end do
            end do
         end do
         if (.not. any_change) exit
         ! next pass: the changed nodes and their neighbours
         dirty = .false.
         do j = 1, np
            do i = 1, nt
               if (.not. changed(i, j)) cycle
               dirty(i, j) = .true.
               do k = 1, 4
                  call neighbour(i, j, k, nt, np, ii, jj)
                  dirty(ii, jj) = .true.
               end do
            end do
         end do
      end do
      counts%newton = count(solved)
      counts%continued = count(from_nb .and. solved)
      counts%fallback = count(.not. solved)
      do j = 1, np
         do i = 1, nt
            if (solved(i, j)) cycle
            call node_frame(surf, i, j, u, e1, e2)
            call definition_radius(surf, u, t, rt(i, j))
         end do
      end do
   end subroutine offset_grid

   !> Newton from every node's sampled start, each direction independently, through a pool of
   !> `pool` slots: directions enter the pool in order with the tabulated derivatives of their
   !> start sample (the first step needs no evaluation); each round takes one Newton step for every
   !> slot (`newton_lanes` on `step_lanes` consecutive slots at a time), retires the finished
   !> directions, keeps the others in order and evaluates the expansion at their new points
   !> (`eval_surface_many`). The groups of lanes stay full (only the last group of a round is
   !> short) and the working arrays are per slot (lane-major, small, on the stack) instead of per
   !> direction of the grid.
   pure subroutine first_pass(surf, t, start, lower, tol, rt, solved, foot, fx, nev)
      type(shell_surface_type), intent(in) :: surf
      real(wp), intent(in) :: t, lower(:, :), tol
      integer, intent(in) :: start(:, :)
      real(wp), intent(out) :: rt(:, :), foot(:, :, :), fx(:, :, :)
      logical(c_bool), intent(out) :: solved(:, :)
      integer, intent(inout) :: nev
      ! (the columns of the lane-major arrays are padded: a power-of-two stride would map a slot's
      ! entries to the same cache set)
      real(wp) :: ts(pool), ps(pool), f(pool + 8, 6), sc(pool + 8, 4), node(pool + 8, 4), rn(pool)
      integer :: di(pool), dj(pool), steps(pool)
      real(wp) :: lxf(step_lanes, 3), lrho(step_lanes)
      integer :: lstate(step_lanes)
      integer :: nt, np, n, k, knext, na, nkeep, i, j, b0, is, js, lm, l, nl, c

      nt = size(rt, 1)
      np = size(rt, 2)
      n = nt * np
      lm = surf%grid%lmax
      rt = 0.0_wp
      fx = 0.0_wp
      ! slots never filled take part in short groups: harmless values (the equator)
      ts = 0.5_wp * pi
      ps = 0.0_wp
      f = 1.0_wp
      sc = 0.0_wp
      sc(:, 1) = 1.0_wp
      sc(:, 4) = 1.0_wp
      node = sc
      rn = 1.0_wp
      knext = 1
      na = 0
      do
         ! fill the free slots with the next directions (node (i, j) is direction i + (j - 1) nt)
         do while (na < pool .and. knext <= n)
            na = na + 1
            k = knext
            knext = knext + 1
            i = 1 + modulo(k - 1, nt)
            j = 1 + (k - 1) / nt
            is = 1 + modulo(start(i, j) - 1, nt)
            js = 1 + (start(i, j) - 1) / nt
            di(na) = i
            dj(na) = j
            steps(na) = 0
            ts(na) = surf%grid%sphere%theta(is)
            ps(na) = surf%grid%sphere%phi(js)
            ! sin/cos of the start node from the grid's tables, derivatives from the sample's table
            sc(na, :) = [surf%grid%sphere%sint(is), surf%grid%sphere%x(is), surf%grid%trig(lm + 2, js), surf%grid%trig(2, js)]
            f(na, :) = surf%f(:, is, js)
            node(na, :) = [surf%grid%sphere%sint(i), surf%grid%sphere%x(i), surf%grid%trig(2, j), surf%grid%trig(lm + 2, j)]
            rn(na) = surf%r(i, j)
         end do
         if (na == 0) exit
         ! one Newton step for every slot, `step_lanes` at a time (a short last group runs on
         ! stale or never-filled slots, results discarded); the running ones are kept in order
         nkeep = 0
         do b0 = 1, na, step_lanes
            nl = min(step_lanes, na - b0 + 1)
            call newton_lanes(pool + 8, node(b0, 1), t, rn(b0), f(b0, 1), sc(b0, 1), ts(b0), ps(b0), lstate, lrho, lxf)
            do l = 1, nl
               c = b0 + l - 1
               i = di(c)
               j = dj(c)
               if (lstate(l) == newton_state%running .and. steps(c) + 1 < max_newton) then
                  ! (nkeep <= c: the slot moves down or stays)
                  nkeep = nkeep + 1
                  di(nkeep) = i
                  dj(nkeep) = j
                  steps(nkeep) = steps(c) + 1
                  ts(nkeep) = ts(c)
                  ps(nkeep) = ps(c)
                  node(nkeep, :) = node(c, :)
                  rn(nkeep) = rn(c)
                  cycle
               end if
               ! retired: converged, failed, or still running after max_newton steps (whose
               ! evaluation after the last step is counted as in a plain loop over the steps)
               if (lstate(l) == newton_state%running) nev = nev + 1
               solved(i, j) = .false.
               if (lstate(l) == newton_state%converged) then
                  rt(i, j) = lrho(l)
                  fx(:, i, j) = lxf(l, :)
                  solved(i, j) = rt(i, j) >= lower(i, j) - tol
               end if
               if (.not. solved(i, j)) rt(i, j) = 0.0_wp
               foot(:, i, j) = [ts(c), ps(c)]
            end do
         end do
         na = nkeep
         if (na > 0) then
            call eval_surface_many(surf, ts(1:na), ps(1:na), f(1:na, :), sc(1:na, :))
            nev = nev + na
         end if
      end do
   end subroutine first_pass

   !> Unit direction and the two perpendicular unit vectors (theta-hat, phi-hat) of node (i, j).
   pure subroutine node_frame(surf, i, j, u, e1, e2)
      type(shell_surface_type), intent(in) :: surf
      integer, intent(in) :: i, j
      real(wp), intent(out) :: u(3), e1(3), e2(3)
      real(wp) :: st, ct, cp, sp
      st = surf%grid%sphere%sint(i)
      ct = surf%grid%sphere%x(i)
      ! cos(phi_j) and sin(phi_j) from the grid's trigonometric table
      cp = surf%grid%trig(2, j)
      sp = surf%grid%trig(surf%grid%lmax + 2, j)
      u = [st * cp, st * sp, ct]
      e1 = [ct * cp, ct * sp, -st]
      e2 = [-sp, cp, 0.0_wp]
   end subroutine node_frame

   !> Neighbour k (1..4: theta -, theta +, phi -, phi +) of node (i, j).
   !> Beyond the first and last rings the neighbour is the same ring across the pole.
   pure subroutine neighbour(i, j, k, nt, np, ii, jj)
      integer, intent(in) :: i, j, k, nt, np
      integer, intent(out) :: ii, jj
      ii = i
      jj = j
      select case (k)
      case (1)
         ii = i - 1
      case (2)
         ii = i + 1
      case (3)
         jj = 1 + modulo(j - 2, np)
      case default
         jj = 1 + modulo(j, np)
      end select
      if (ii < 1 .or. ii > nt) then
         ii = i
         jj = 1 + modulo(j - 1 + np / 2, np)
      end if
   end subroutine neighbour

   !> Per direction node: the largest sampled lower bound m(u) = max_s g_u(x_s) (-huge if no sample
   !> is within t of the ray) and the start sample (best g, else best-aligned offset direction),
   !> start = i + (j - 1) ntheta for sample (i, j).
   !> The samples form cells (grid-adjacent quadruples, the polar caps closed by triangles to the
   !> pole); the offset map sends a cell to the spherical patch spanned by its corners' offset
   !> directions, so each cell's corners must be tried on the direction nodes inside the
   !> (theta, phi) box of those directions, widened by a quarter spacing. The node of every
   !> direction lies in the image of the cell holding its true foot, whose corners are within one
   !> cell of it. Each sample is tried once on the box of the union of its (up to four) cells,
   !> which holds every cell box it belongs to (near the poles, where a cell box is a whole ring,
   !> a pair is then tried once instead of once per cell).
   pure subroutine sampled_starts(surf, t, lower, start)
      type(shell_surface_type), intent(in) :: surf
      real(wp), intent(in) :: t
      real(wp), intent(out) :: lower(:, :)
      integer, intent(out) :: start(:, :)
      real(wp), allocatable :: qth(:, :), qph(:, :), align(:, :)
      real(wp), allocatable :: bthlo(:), bthhi(:), bphlo(:), bphhi(:)
      real(wp), allocatable :: px(:), py(:), pz(:), nx(:), ny(:), nz(:)
      integer, allocatable :: rows(:)
      real(wp) :: q(3), qd(3), mth, mph, thlo, thhi, phlo, phhi, d, t2, c, dphi, rscale
      real(wp) :: pole(3), pole_dir(3, 2), xs(3), xxs, du, perp2, dd, ph0, w
      integer :: nt, np, i, j, ii, jb, ia, ja, jc, i0, i1, j0, ncol, kc, jn(3), lm, code
      logical :: all_phi, have_qd

      nt = surf%grid%sphere%ntheta
      np = surf%grid%sphere%nphi
      lm = surf%grid%lmax
      dphi = two_pi / np
      allocate (qth(nt, np), qph(nt, np), align(nt, np), bthlo(nt), bthhi(nt), bphlo(nt), bphhi(nt), &
                px(nt), py(nt), pz(nt), nx(nt), ny(nt), nz(nt))
      call offset_directions(surf, t, qth, qph, pole_dir, start)
      do kc = 1, 2
         pole_dir(:, kc) = pole_dir(:, kc) / norm2(pole_dir(:, kc))
      end do
      rows = row_table(surf%grid%sphere%theta)
      rscale = size(rows) / pi
      lower = -huge(1.0_wp)
      align = -2.0_wp
      mth = 0.25_wp * pi / nt
      mph = 0.25_wp * dphi
      t2 = t * t
      do j = 1, np
         call column_geometry(surf, j, px, py, pz, nx, ny, nz)
         ! sample (i, j) is tried on the nodes in the box of the union of the (up to four) cells
         ! it is a corner of: the offset directions of rows i - 1..i + 1, columns j - 1..j + 1
         ! (azimuths relative to the sample's own, unwrapped), and across a pole the pole's offset
         ! direction (the polar triangles). Every pair (node, corner) of a cell box is in it; near
         ! the poles, where a cell's box is a whole ring, each pair is tried once instead of once
         ! per cell. The boxes of a column first, in plain loops over the rows.
         jn = [1 + modulo(j - 2, np), j, 1 + modulo(j, np)]
         bthlo = pi
         bthhi = 0.0_wp
         bphlo = 0.0_wp
         bphhi = 0.0_wp
         do jc = 1, 3
            jb = jn(jc)
            do ii = -1, 1
               do i = max(1, 1 - ii), min(nt, nt - ii)
                  bthlo(i) = min(bthlo(i), qth(i + ii, jb))
                  bthhi(i) = max(bthhi(i), qth(i + ii, jb))
                  ! qph values are atan2 values in [-pi, pi]: one turn at most brings the
                  ! difference into [-pi, pi)
                  d = qph(i + ii, jb) - qph(i, j)
                  d = merge(d - two_pi, merge(d + two_pi, d, d < -pi), d >= pi)
                  bphlo(i) = min(bphlo(i), d)
                  bphhi(i) = max(bphhi(i), d)
               end do
            end do
         end do
         do i = 1, nt
            ph0 = qph(i, j)
            thlo = bthlo(i)
            thhi = bthhi(i)
            phlo = bphlo(i)
            phhi = bphhi(i)
            if (i == 1 .or. i == nt) then
               pole = pole_dir(:, merge(1, 2, i == 1))
               d = acos(max(-1.0_wp, min(1.0_wp, pole(3))))
               if (min(d, pi - d) < 0.5_wp * minval(surf%grid%sphere%theta)) then
                  ! at the pole itself (closer than any node): its azimuth is meaningless
                  thlo = min(thlo, d)
                  thhi = max(thhi, d)
               else
                  call widen(d, atan2(pole(2), pole(1)), ph0, thlo, thhi, phlo, phhi)
               end if
            end if
            ! the sample's offset direction, normalised when first needed
            xs = [px(i), py(i), pz(i)]
            q = xs + t * [nx(i), ny(i), nz(i)]
            have_qd = .false.
            all_phi = phhi - phlo > pi
            if (all_phi) then
               ! the patch holds a pole
               if (q(3) > 0.0_wp) then
                  thlo = 0.0_wp
               else
                  thhi = pi
               end if
            end if
            call row_range(surf%grid%sphere%theta, rows, rscale, thlo - mth, thhi + mth, i0, i1)
            if (all_phi) then
               j0 = 1
               ncol = np
            else
               phlo = ph0 + phlo - mph
               phhi = ph0 + phhi + mph
               j0 = ceiling(phlo / dphi) + 1
               ncol = floor(phhi / dphi) + 2 - j0
            end if
            xxs = dot_product(xs, xs)
            code = i + (j - 1) * nt
            ja = 1 + modulo(j0 - 2, np)
            do jc = 1, ncol
               ja = ja + 1
               if (ja > np) ja = 1
               ! node direction (sin t cos p, sin t sin p, cos t): u . xs = sin t w + cos t xs(3)
               w = surf%grid%trig(2, ja) * xs(1) + surf%grid%trig(lm + 2, ja) * xs(2)
               do ia = i0, i1
                  du = surf%grid%sphere%sint(ia) * w + surf%grid%sphere%x(ia) * xs(3)
                  perp2 = xxs - du * du
                  if (perp2 < t2) then
                     ! g_u = du + sqrt(t^2 - perp^2) > bound, decided without the square root
                     ! (dd clamped below so that an unset bound does not overflow)
                     dd = max(lower(ia, ja) - du, -1.0_wp)
                     if (dd < 0.0_wp .or. t2 - perp2 > dd * dd) then
                        lower(ia, ja) = du + sqrt(t2 - perp2)
                        start(ia, ja) = code
                     end if
                  else if (lower(ia, ja) == -huge(1.0_wp)) then
                     ! no sample within t of this ray yet: the best-aligned offset direction
                     if (.not. have_qd) then
                        qd = q / sqrt(dot_product(q, q))
                        have_qd = .true.
                     end if
                     c = surf%grid%sphere%sint(ia) * (surf%grid%trig(2, ja) * qd(1) + surf%grid%trig(lm + 2, ja) * qd(2)) &
                         + surf%grid%sphere%x(ia) * qd(3)
                     if (c > align(ia, ja)) then
                        align(ia, ja) = c
                        start(ia, ja) = code
                     end if
                  end if
               end do
            end do
         end do
      end do
   end subroutine sampled_starts

   !> Offset points x + t n of the samples: the polar angles and azimuths of their directions and
   !> their sums over the first and last rings (towards the poles); one column at a time in plain
   !> loops (the compiler vectorises acos and atan2).
   pure subroutine offset_directions(surf, t, qth, qph, pole_dir, start)
      !> Surface data.
      type(shell_surface_type), intent(in) :: surf
      !> Offset distance.
      real(wp), intent(in) :: t
      !> Polar angle and azimuth of each sample's offset point (nt, np).
      real(wp), intent(out) :: qth(:, :), qph(:, :)
      !> Sums of the offset points of the first (1) and last (2) rings.
      real(wp), intent(out) :: pole_dir(3, 2)
      !> Each sample its own start (its index).
      integer, intent(out) :: start(:, :)
      real(wp), allocatable :: qx(:), qy(:), qz(:), qn(:), px(:), py(:), pz(:), nx(:), ny(:), nz(:)
      integer :: nt, np, i, j

      nt = surf%grid%sphere%ntheta
      np = surf%grid%sphere%nphi
      allocate (qx(nt), qy(nt), qz(nt), qn(nt), px(nt), py(nt), pz(nt), nx(nt), ny(nt), nz(nt))
      pole_dir = 0.0_wp
      do j = 1, np
         call column_geometry(surf, j, px, py, pz, nx, ny, nz)
         do i = 1, nt
            qx(i) = px(i) + t * nx(i)
            qy(i) = py(i) + t * ny(i)
            qz(i) = pz(i) + t * nz(i)
            qn(i) = sqrt(qx(i) * qx(i) + qy(i) * qy(i) + qz(i) * qz(i))
         end do
         do i = 1, nt
            qth(i, j) = acos(max(-1.0_wp, min(1.0_wp, qz(i) / qn(i))))
            qph(i, j) = atan2(qy(i) / qn(i), qx(i) / qn(i))
         end do
         pole_dir(:, 1) = pole_dir(:, 1) + [qx(1), qy(1), qz(1)]
         pole_dir(:, 2) = pole_dir(:, 2) + [qx(nt), qy(nt), qz(nt)]
         start(:, j) = [(i + (j - 1) * nt, i = 1, nt)]
      end do
   end subroutine offset_directions

   !> Widen the box [thlo, thhi] x [phlo, phhi] (phi relative to ph0, unwrapped) to hold (th, ph).
   pure subroutine widen(th, ph, ph0, thlo, thhi, phlo, phhi)
      real(wp), intent(in) :: th, ph, ph0
      real(wp), intent(inout) :: thlo, thhi, phlo, phhi
      real(wp) :: d
      thlo = min(thlo, th)
      thhi = max(thhi, th)
      ! ph and ph0 are atan2 values in [-pi, pi]: one turn at most brings d into [-pi, pi)
      d = ph - ph0
      if (d >= pi) then
         d = d - two_pi
      else if (d < -pi) then
         d = d + two_pi
      end if
      phlo = min(phlo, d)
      phhi = max(phhi, d)
   end subroutine widen

   !> Table for `row_range`: rows(b) = the first row with theta >= b pi / nb, b = 0..nb - 1, nb at
   !> least 64 times the row count (so that few values share a bin with a row: the correction in
   !> `first_at_least` is then rarely taken) and such that no bin holds two rows (an empty table
   !> when theta does not increase: `row_range` then scans).
   pure function row_table(theta) result(rows)
      real(wp), intent(in) :: theta(:)
      integer, allocatable :: rows(:)
      integer :: n, nb, b, k

      n = size(theta)
      allocate (rows(0))
      if (n < 2) return
      if (any(theta(2:n) <= theta(1:n - 1))) return
      nb = 64 * n
      do while (nb < 1024 * n)
         if (all(theta(2:n) - theta(1:n - 1) > pi / nb)) exit
         nb = 2 * nb
      end do
      deallocate (rows)
      allocate (rows(0:nb - 1))
      k = 1
      do b = 0, nb - 1
         do while (k <= n)
            if (theta(k) >= b * (pi / nb)) exit
            k = k + 1
         end do
         rows(b) = k
      end do
   end function row_table

   !> Rows i0..i1 whose theta lies in [lo, hi] (theta monotone in i, `rows` from `row_table`,
   !> scale = size(rows) / pi); i1 < i0 when none.
   pure subroutine row_range(theta, rows, scale, lo, hi, i0, i1)
      real(wp), intent(in) :: theta(:), scale, lo, hi
      integer, intent(in) :: rows(0:)
      integer, intent(out) :: i0, i1
      integer :: i
      i0 = size(theta) + 1
      i1 = 0
      if (size(rows) > 0) then
         i0 = first_at_least(theta, rows, scale, lo)
         i1 = first_at_least(theta, rows, scale, hi) - 1
         if (i1 < size(theta)) then
            if (theta(i1 + 1) <= hi) i1 = i1 + 1
         end if
      else
         do i = 1, size(theta)
            if (theta(i) >= lo .and. theta(i) <= hi) then
               i0 = min(i0, i)
               i1 = max(i1, i)
            end if
         end do
      end if
   end subroutine row_range

   !> Smallest i with theta(i) >= v for increasing theta (size + 1 if none): the table's row for
   !> the bin of v, corrected by a walk (at most one row holds in a bin).
   pure function first_at_least(theta, rows, scale, v) result(k)
      real(wp), intent(in) :: theta(:), scale, v
      integer, intent(in) :: rows(0:)
      integer :: k, n
      n = size(theta)
      k = rows(int(max(0.0_wp, min(real(size(rows) - 1, wp), v * scale))))
      ! (the walks take a step only at a row inside the bin of v, or by rounding of the bin)
      do while (k > 1)
         if (theta(k - 1) < v) exit
         k = k - 1
      end do
      do while (k <= n)
         if (theta(k) >= v) exit
         k = k + 1
      end do
   end function first_at_least

   !> Newton-Raphson for Eq 2.1 along u (theta-hat e1, phi-hat e2 span the plane perpendicular to
   !> u) from (ts, ps); f0, when present, holds r and its derivatives at the start (the first step
   !> then needs no evaluation). See `newton_update` for the finish and the local conditions.
   pure subroutine foot_newton(surf, u, e1, e2, t, rnode, ts, ps, rho, xf, ok, nev, f0)
      type(shell_surface_type), intent(in) :: surf
      real(wp), intent(in) :: u(3), e1(3), e2(3), t, rnode
      real(wp), intent(inout) :: ts, ps
      real(wp), intent(out) :: rho, xf(3)
      logical, intent(out) :: ok
      integer, intent(out) :: nev
      real(wp), intent(in), optional :: f0(6)
      real(wp) :: f(6)
      integer :: it, state

      ok = .false.
      rho = 0.0_wp
      xf = 0.0_wp
      nev = 0
      if (present(f0)) then
         f = f0
      else
         if (abs(sin(ts)) < pole_sin) return
         call eval_surface(surf, ts, ps, f)
         nev = 1
      end if
      do it = 1, max_newton
         call newton_update(u, e1, e2, t, rnode, f, [sin(ts), cos(ts), sin(ps), cos(ps)], ts, ps, state, rho, xf)
         if (state /= newton_state%running) exit
         call eval_surface(surf, ts, ps, f)
         nev = nev + 1
      end do
      ok = state == newton_state%converged
   end subroutine foot_newton

   !> One Newton step for Eq 2.1 at (ts, ps) with f = r and its derivatives there. Once the step is
   !> below `finish_step` the root is finished by a second-order Taylor step, rho = g_u(x + x_t dt +
   !> x_p dp + second-order terms), and state = converged if the local conditions hold (beta > 0 with
   !> rnode = r(u), u . n > 0, strict local minimum of the distance: 1 - t kappa_i > 0), else failed.
   !> Otherwise (ts, ps) takes the (damped) step and state = running (failed near the poles).
   pure subroutine newton_update(u, e1, e2, t, rnode, f, sc, ts, ps, state, rho, xf)
      real(wp), intent(in) :: u(3), e1(3), e2(3), t, rnode, f(6), sc(4)
      real(wp), intent(inout) :: ts, ps
      integer, intent(out) :: state
      real(wp), intent(out) :: rho, xf(3)
      real(wp) :: x(3), xt(3), xp(3), xtt(3), xtp(3), xpp(3), x2(3)
      real(wp) :: nv(3), nt(3), np(3), nn, nh(3), q(3), qt(3), qp(3), sgn
      real(wp) :: f1, f2, j11, j12, j21, j22, det, dt, dp, lam, h11, h12, h22, du, perp2

      state = newton_state%failed
      rho = 0.0_wp
      xf = 0.0_wp
      call surface_frame_trig(sc, f, x, xt, xp, xtt, xtp, xpp)
      sgn = sign(1.0_wp, sc(1))
      nv = sgn * cross(xt, xp)
      nn = sqrt(dot_product(nv, nv))
      nh = nv / nn
      nt = sgn * (cross(xtt, xp) + cross(xt, xtp))
      np = sgn * (cross(xtp, xp) + cross(xt, xpp))
      nt = (nt - nh * dot_product(nh, nt)) / nn
      np = (np - nh * dot_product(nh, np)) / nn
      q = x + t * nh
      qt = xt + t * nt
      qp = xp + t * np
      f1 = dot_product(q, e1)
      f2 = dot_product(q, e2)
      j11 = dot_product(qt, e1)
      j12 = dot_product(qp, e1)
      j21 = dot_product(qt, e2)
      j22 = dot_product(qp, e2)
      det = j11 * j22 - j12 * j21
      if (.not. abs(det) > tiny(det) * 1.0e10_wp) return
      dt = -(j22 * f1 - j12 * f2) / det
      dp = -(j11 * f2 - j21 * f1) / det
      if (max(abs(dt), abs(dp)) <= finish_step) then
         h11 = dot_product(xt, xt) - t * dot_product(nh, xtt)
         h12 = dot_product(xt, xp) - t * dot_product(nh, xtp)
         h22 = dot_product(xp, xp) - t * dot_product(nh, xpp)
         if (.not. (h11 > 0.0_wp .and. h11 * h22 - h12 * h12 > 0.0_wp .and. dot_product(nh, u) > 0.0_wp)) return
         x2 = x + xt * dt + xp * dp + 0.5_wp * (xtt * dt * dt + 2.0_wp * xtp * dt * dp + xpp * dp * dp)
         du = dot_product(u, x2)
         perp2 = max(0.0_wp, dot_product(x2, x2) - du * du)
         if (perp2 > t * t) return
         rho = du + sqrt(t * t - perp2)
         xf = x2
         ts = ts + dt
         ps = ps + dp
         if (rho > rnode) state = newton_state%converged
         return
      end if
      lam = min(1.0_wp, 0.2_wp / max(abs(dt), abs(dp)))
      ts = ts + lam * dt
      ps = ps + lam * dp
      if (abs(sin(ts)) >= pole_sin) state = newton_state%running
   end subroutine newton_update

   !> `newton_update` for `step_lanes` directions at once (one direction per lane; arrays
   !> (lane, component), branches as masks), the same arithmetic and the same outcomes. The
   !> lane inputs are the first `step_lanes` rows of arrays with leading dimension ld (node: the
   !> node's sin theta, cos theta, cos phi, sin phi; f and sc as from `eval_surface_many`).
   pure subroutine newton_lanes(ld, nodein, t, rnode, fin, scin, ts, ps, state, rho, xf)
      integer, intent(in) :: ld
      real(wp), intent(in) :: nodein(ld, 4), t, rnode(step_lanes)
      real(wp), intent(in) :: fin(ld, 6), scin(ld, 4)
      real(wp), intent(inout) :: ts(step_lanes), ps(step_lanes)
      integer, intent(out) :: state(step_lanes)
      real(wp), intent(out) :: rho(step_lanes), xf(step_lanes, 3)
      real(wp) :: node(step_lanes, 4), f(step_lanes, 6), sc(step_lanes, 4)
      real(wp), dimension(step_lanes, 3) :: rh, th, x, xt, xp, xtt, xtp, xpp, nv, nh, nt, np, q, qt, qp, x2, u, e1, e2
      real(wp), dimension(step_lanes) :: st, ct, sp, cp, sgn, nn, inn, dnt, dnp, f1, f2, j11, j12, j21, j22, det, &
                                         dt, dp, h11, h12, h22, du, perp2, big, lam, cu, a, r1, sts
      logical, dimension(step_lanes) :: good, finish, ok
      integer :: c

      node = nodein(1:step_lanes, :)
      f = fin(1:step_lanes, :)
      sc = scin(1:step_lanes, :)
      ! the node's direction u and the perpendicular unit vectors theta-hat, phi-hat (`node_frame`)
      u(:, 1) = node(:, 1) * node(:, 3)
      u(:, 2) = node(:, 1) * node(:, 4)
      u(:, 3) = node(:, 2)
      e1(:, 1) = node(:, 2) * node(:, 3)
      e1(:, 2) = node(:, 2) * node(:, 4)
      e1(:, 3) = -node(:, 1)
      e2(:, 1) = -node(:, 4)
      e2(:, 2) = node(:, 3)
      e2(:, 3) = 0.0_wp

      st = sc(:, 1)
      ct = sc(:, 2)
      sp = sc(:, 3)
      cp = sc(:, 4)
      rh(:, 1) = st * cp
      rh(:, 2) = st * sp
      rh(:, 3) = ct
      th(:, 1) = ct * cp
      th(:, 2) = ct * sp
      th(:, 3) = -st
      r1 = f(:, 1)
      do c = 1, 3
         x(:, c) = r1 * rh(:, c)
         xt(:, c) = f(:, 2) * rh(:, c) + r1 * th(:, c)
         xtt(:, c) = (f(:, 4) - r1) * rh(:, c) + 2.0_wp * f(:, 2) * th(:, c)
         xtp(:, c) = f(:, 5) * rh(:, c) + f(:, 3) * th(:, c)
         xpp(:, c) = f(:, 6) * rh(:, c)
         xp(:, c) = f(:, 3) * rh(:, c)
      end do
      ! phi-hat = (-sin phi, cos phi, 0) and rho-hat = (cos phi, sin phi, 0) terms
      a = f(:, 2) * st + r1 * ct
      xp(:, 1) = xp(:, 1) - r1 * st * sp
      xp(:, 2) = xp(:, 2) + r1 * st * cp
      xtp(:, 1) = xtp(:, 1) - a * sp
      xtp(:, 2) = xtp(:, 2) + a * cp
      xpp(:, 1) = xpp(:, 1) - 2.0_wp * f(:, 3) * st * sp - r1 * st * cp
      xpp(:, 2) = xpp(:, 2) + 2.0_wp * f(:, 3) * st * cp - r1 * st * sp
      sgn = sign(1.0_wp, st)
      call cross_lanes(xt, xp, nv)
      call cross_lanes(xtt, xp, nt)
      call cross_lanes(xt, xtp, q)
      call cross_lanes(xtp, xp, np)
      call cross_lanes(xt, xpp, qt)
      do c = 1, 3
         nv(:, c) = sgn * nv(:, c)
         nt(:, c) = sgn * (nt(:, c) + q(:, c))
         np(:, c) = sgn * (np(:, c) + qt(:, c))
      end do
      nn = sqrt(nv(:, 1)**2 + nv(:, 2)**2 + nv(:, 3)**2)
      inn = 1.0_wp / nn
      do c = 1, 3
         nh(:, c) = nv(:, c) * inn
      end do
      dnt = nh(:, 1) * nt(:, 1) + nh(:, 2) * nt(:, 2) + nh(:, 3) * nt(:, 3)
      dnp = nh(:, 1) * np(:, 1) + nh(:, 2) * np(:, 2) + nh(:, 3) * np(:, 3)
      do c = 1, 3
         nt(:, c) = (nt(:, c) - nh(:, c) * dnt) * inn
         np(:, c) = (np(:, c) - nh(:, c) * dnp) * inn
         q(:, c) = x(:, c) + t * nh(:, c)
         qt(:, c) = xt(:, c) + t * nt(:, c)
         qp(:, c) = xp(:, c) + t * np(:, c)
      end do
      f1 = dot_lanes(q, e1)
      f2 = dot_lanes(q, e2)
      j11 = dot_lanes(qt, e1)
      j12 = dot_lanes(qp, e1)
      j21 = dot_lanes(qt, e2)
      j22 = dot_lanes(qp, e2)
      det = j11 * j22 - j12 * j21
      good = abs(det) > tiny(det) * 1.0e10_wp
      det = merge(det, 1.0_wp, good)
      dt = -(j22 * f1 - j12 * f2) / det
      dp = -(j11 * f2 - j21 * f1) / det
      big = max(abs(dt), abs(dp))
      finish = good .and. big <= finish_step
      ! finished lanes: local conditions and the second-order Taylor root
      h11 = dot_lanes(xt, xt) - t * dot_lanes(nh, xtt)
      h12 = dot_lanes(xt, xp) - t * dot_lanes(nh, xtp)
      h22 = dot_lanes(xp, xp) - t * dot_lanes(nh, xpp)
      cu = dot_lanes(nh, u)
      do c = 1, 3
         x2(:, c) = x(:, c) + xt(:, c) * dt + xp(:, c) * dp + 0.5_wp * (xtt(:, c) * dt * dt &
                    + 2.0_wp * xtp(:, c) * dt * dp + xpp(:, c) * dp * dp)
      end do
      du = dot_lanes(u, x2)
      perp2 = max(0.0_wp, dot_lanes(x2, x2) - du * du)
      ok = finish .and. h11 > 0.0_wp .and. h11 * h22 - h12 * h12 > 0.0_wp .and. cu > 0.0_wp .and. perp2 <= t * t
      rho = merge(du + sqrt(max(0.0_wp, t * t - perp2)), 0.0_wp, ok)
      do c = 1, 3
         xf(:, c) = merge(x2(:, c), 0.0_wp, ok)
      end do
      ! running lanes: the damped step
      lam = min(1.0_wp, 0.2_wp / merge(big, 1.0_wp, good .and. .not. finish))
      lam = merge(lam, 1.0_wp, .not. finish)
      where (ok .or. (good .and. .not. finish))
         ts = ts + lam * dt
         ps = ps + lam * dp
      end where
      state = newton_state%failed
      where (ok .and. rho > rnode) state = newton_state%converged
      ! (sin of every lane, unconditionally: one vector call)
      sts = abs(sin(ts))
      where (good .and. .not. finish)
         state = merge(newton_state%running, newton_state%failed, sts >= pole_sin)
      end where
   end subroutine newton_lanes

   !> c = a x b per lane.
   pure subroutine cross_lanes(a, b, c)
      real(wp), intent(in) :: a(:, :), b(:, :)
      real(wp), intent(out) :: c(:, :)
      c(:, 1) = a(:, 2) * b(:, 3) - a(:, 3) * b(:, 2)
      c(:, 2) = a(:, 3) * b(:, 1) - a(:, 1) * b(:, 3)
      c(:, 3) = a(:, 1) * b(:, 2) - a(:, 2) * b(:, 1)
   end subroutine cross_lanes

   !> a . b per lane.
   pure function dot_lanes(a, b) result(d)
      real(wp), intent(in) :: a(:, :), b(:, :)
      real(wp) :: d(size(a, 1))
      d = a(:, 1) * b(:, 1) + a(:, 2) * b(:, 2) + a(:, 3) * b(:, 3)
   end function dot_lanes

   include "anm_cross.inc"

   !> The sample whose offset point x_s + t n_s is best aligned with u (the Newton start).
   pure subroutine start_point(surf, u, t, ts, ps)
      type(shell_surface_type), intent(in) :: surf
      real(wp), intent(in) :: u(3), t
      real(wp), intent(out) :: ts, ps
      real(wp) :: q(3), c, best, alpha, tu, pu, width, dphi, xs(3), ns(3)
      integer :: i, j, jj, ib, jb, nt, np, j0, ncol
      logical :: all_phi

      nt = surf%grid%sphere%ntheta
      np = surf%grid%sphere%nphi
      dphi = two_pi / np
      ! the offset point of a surface point at angle > alpha from u cannot lie on the ray
      alpha = asin(min(1.0_wp, t / max(surf%rmin, tiny(t)))) + 2.0_wp * pi / nt
      tu = acos(max(-1.0_wp, min(1.0_wp, u(3))))
      pu = modulo(atan2(u(2), u(1)), two_pi)
      all_phi = tu - alpha <= 0.0_wp .or. tu + alpha >= pi
      if (.not. all_phi) then
         width = asin(min(1.0_wp, sin(alpha) / sin(tu))) + 2.0_wp * dphi
         all_phi = width >= pi .or. sin(alpha) >= sin(tu)
      end if
      if (all_phi) then
         j0 = 1
         ncol = np
      else
         j0 = floor((pu - width) / dphi) + 1
         ncol = floor((pu + width) / dphi) + 2 - j0
      end if
      best = -2.0_wp
      ib = 1
      jb = 1
      do jj = 1, ncol
         j = 1 + modulo(j0 + jj - 2, np)
         do i = 1, nt
            if (abs(surf%grid%sphere%theta(i) - tu) > alpha) cycle
            call node_geometry(surf, i, j, xs, ns)
            q = xs + t * ns
            c = dot_product(q, u) / norm2(q)
            if (c > best) then
               best = c
               ib = i
               jb = j
            end if
         end do
      end do
      ts = surf%grid%sphere%theta(ib)
      ps = surf%grid%sphere%phi(jb)
   end subroutine start_point

   !> Newton-Raphson for Eq 2.1 from (ts, ps): on success rho = r(theta, phi) + beta, the offset
   !> point is rho u, and the root passed the local checks (beta > 0, u . n > 0, local minimum).
   pure subroutine offset_newton(surf, theta, phi, t, ts, ps, rho, ok)
      !> Surface data.
      type(shell_surface_type), intent(in) :: surf
      !> Target direction.
      real(wp), intent(in) :: theta, phi
      !> Thickness.
      real(wp), intent(in) :: t
      !> Start (theta', phi'); the root on output.
      real(wp), intent(inout) :: ts, ps
      !> Distance of the offset point from the centre.
      real(wp), intent(out) :: rho
      !> Converged and locally valid.
      logical, intent(out) :: ok
      real(wp) :: u(3), e1(3), e2(3), f(6), x(3), xt(3), xp(3), xtt(3), xtp(3), xpp(3)
      real(wp) :: nv(3), nt(3), np(3), nn, nh(3), q(3), qt(3), qp(3), sgn
      real(wp) :: f1, f2, j11, j12, j21, j22, det, dt, dp, lam, res, scale
      real(wp) :: h11, h12, h22
      integer :: it

      u = [sin(theta) * cos(phi), sin(theta) * sin(phi), cos(theta)]
      e1 = [cos(theta) * cos(phi), cos(theta) * sin(phi), -sin(theta)]
      e2 = [-sin(phi), cos(phi), 0.0_wp]
      scale = surf%rmax + t
      ok = .false.
      rho = 0.0_wp
      do it = 1, 30
         if (abs(sin(ts)) < 1.0e-6_wp) return
         call eval_surface(surf, ts, ps, f)
         call surface_frame(ts, ps, f, x, xt, xp, xtt, xtp, xpp)
         sgn = sign(1.0_wp, sin(ts))
         nv = sgn * cross3(xt, xp)
         nn = norm2(nv)
         nh = nv / nn
         nt = sgn * (cross3(xtt, xp) + cross3(xt, xtp))
         np = sgn * (cross3(xtp, xp) + cross3(xt, xpp))
         nt = (nt - nh * dot_product(nh, nt)) / nn
         np = (np - nh * dot_product(nh, np)) / nn
         q = x + t * nh
         qt = xt + t * nt
         qp = xp + t * np
         f1 = dot_product(q, e1)
         f2 = dot_product(q, e2)
         res = sqrt(f1 * f1 + f2 * f2)
         if (res < 1.0e-13_wp * scale) then
            rho = dot_product(q, u)
            h11 = dot_product(xt, xt) - t * dot_product(nh, xtt)
            h12 = dot_product(xt, xp) - t * dot_product(nh, xtp)
            h22 = dot_product(xp, xp) - t * dot_product(nh, xpp)
            ok = rho > f(1) * dot_product(x / norm2(x), u) .and. dot_product(nh, u) > 0.0_wp &
                 .and. h11 > 0.0_wp .and. h11 * h22 - h12 * h12 > 0.0_wp .and. dot_product(q, u) > 0.0_wp
            if (ok) ok = rho > surf%shape%radius_dir(u)
            return
         end if
         j11 = dot_product(qt, e1)
         j12 = dot_product(qp, e1)
         j21 = dot_product(qt, e2)
         j22 = dot_product(qp, e2)
         det = j11 * j22 - j12 * j21
         if (abs(det) < tiny(det) * 1.0e10_wp) return
         dt = -(j22 * f1 - j12 * f2) / det
         dp = -(j11 * f2 - j21 * f1) / det
         lam = min(1.0_wp, 0.2_wp / max(abs(dt), abs(dp), tiny(dt)))
         ts = ts + lam * dt
         ps = ps + lam * dp
      end do
   end subroutine offset_newton

   !> R_t(u) = max{rho : dist(rho u, particle) <= t}: safeguarded Newton on
   !> g(rho) = dist(rho u) - t (g' = u . (y - x_c) / |y - x_c|) inside a shrinking bracket.
   pure subroutine definition_radius(surf, u, t, rt)
      type(shell_surface_type), intent(in) :: surf
      real(wp), intent(in) :: u(3), t
      real(wp), intent(out) :: rt
      real(wp) :: lo, hi, rho, d, thc, phc, f(6), xc(3), g1, rnew, tol
      integer :: it

      ! rho = r(u) + t is within t of the surface point r(u) u; beyond rmax + t nothing is
      lo = surf%shape%radius_dir(u) + t
      hi = 1.05_wp * surf%rmax + t + surf%hmax
      tol = 1.0e-12_wp * hi
      rho = 0.5_wp * (lo + hi)
      do it = 1, 200
         call surface_distance(surf, rho * u, t, d, thc, phc)
         if (d <= t) then
            lo = rho
         else
            hi = rho
         end if
         if (hi - lo <= tol) exit
         rnew = -1.0_wp
         if (d < huge(d)) then
            call eval_surface(surf, thc, phc, f)
            xc = f(1) * [sin(thc) * cos(phc), sin(thc) * sin(phc), cos(thc)]
            g1 = dot_product(u, rho * u - xc) / max(d, tiny(d))
            if (abs(d - t) <= 1.0e-12_wp * t .and. g1 > 0.0_wp) then
               rt = rho
               return
            end if
            if (g1 > 1.0e-3_wp) rnew = rho - (d - t) / g1
         end if
         if (rnew <= lo .or. rnew >= hi) rnew = 0.5_wp * (lo + hi)
         rho = rnew
      end do
      rt = 0.5_wp * (lo + hi)
   end subroutine definition_radius
end module anm_shells_offset
