!> Particle-particle and particle-wall contact tests (thesis sections 1.2, 2.2 and 2.5.1).
!>
!> EOB method, staged as the thesis' Fig 2.2 with cheap stages first:
!>  1. bounding spheres (certified r_max: apart -> no contact) and inscribed spheres (certified
!>     r_min: overlap -> contact);
!>  1b. support functions along the line of centres (`support_bound`, one table read per body):
!>     a separating plane normal to the line, wider than the certified gap tolerance -> no contact;
!>  2. overlap along the line of centres (two radius evaluations);
!>  2b. (certified mode) the table's surface point of each body that reaches furthest towards the
!>     other, tested inside the other (one radius evaluation each) -> contact;
!>  3. extent boxes in the world and their intersection, the EOB (empty -> no contact);
!>  4. for each body, its surface is tested against the other body through the patch hierarchy:
!>     a patch whose shell-sector ball misses the EOB, or whose ball lies certainly outside the
!>     other body, is pruned; a ball certainly inside means contact. The other body's r over the
!>     ball's cap of directions is bounded by its stored patch bounds over the index rectangle
!>     that covers the cap (`classify_ball`, no search), and, when these do not decide and the cap
!>     is small, by the local bound r(u0) +- (|grad r(u0)| beta + H beta^2/2) at the cap centre.
!>     Undecided patches of the finest stored level (pi/256 rad) are scanned at N_box resolution
!>     (default mode) or subdivided with local bounds (certified mode). Both bodies are scanned
!>     (a thin protrusion of B into A is invisible from A's surface alone).
!> Each scanned surface point is tested against the other body along the ray to its centre.
!>
!> Certified mode: "no contact" is returned only when every patch was proven outside, so it is
!> guaranteed (up to floating-point rounding). Undecided patches are subdivided; their centre
!> surface point p is tested against the other body along the ray to its centre: inside means
!> contact, and a radial distance to the other surface below `gap` x L (L the smaller body's
!> certified extent, see `contact_params_type`) also reports contact, so a reported contact
!> between non-overlapping bodies implies a surface gap below gap x L. Patches still undecided at
!> `resolution` (a floor never reached in our tests) are reported as contact too.
!>
!> Newton-Raphson method (thesis Eq 1.5, legacy baseline): phi_1 is fixed on `nr_lines` values;
!> the remaining unknowns are eliminated by measuring the surface point of A along the ray from
!> B's centre, g(theta_1) = |y| - r_B(y/|y|), solved by Newton from `nr_starts` starting points.
!> A root is a common surface point; contact is reported when one is found (or when a centre
!> lies inside the other body).
!>
!> Usage:
!>     type(contact_params_type) :: params
!>     hit = bodies_overlap(body_a, ca, rot_a, sa, body_b, cb, rot_b, sb, params)
!>     depth = overlap_depth(body_a, ca, rot_a, sa, body_b, cb, rot_b, sb, params%nbox)
!>     out = body_crosses_walls(body_a, ca, rot_a, sa, [lx, ly, lz])
module anm_contact_overlap
   use anm_core_kinds, only: wp, pi, two_pi
   use anm_contact_body, only: contact_body_type, leaf_level, stored_level, patch_rows, patch_cols, patch_index, &
      & patch_cap, sector_ball, default_next, patch_geometry, patch_bounds, slope_bound, node_size, nd_dir, nd_cosa, &
      & nd_sina, nd_c, nd_r, nd_e, nd_h, nd_ball, nd_brad, nd_rc, support_bound, support_cell
   implicit none
   private

   public :: contact_method, contact_params_type, bodies_overlap, overlap_early, first_stages, overlap_depth, body_crosses_walls, &
      & point_inside, sector_range, boxes_disjoint, cap_bounds, cap_outside, cap_inside

   !> Contact methods.
   type :: contact_method_enum
      !> Extent overlap box with the patch hierarchy (default).
      integer :: eob = 1
      !> Legacy Newton-Raphson on Eq 1.5.
      integer :: newton_raphson = 2
   end type contact_method_enum

   !> The contact methods, used as `contact_method%eob`.
   type(contact_method_enum), parameter :: contact_method = contact_method_enum()

   !> Parameters of the contact test.
   type :: contact_params_type
      !> Method, one of `contact_method`.
      integer :: method = contact_method%eob
      !> N_ext of the thesis extent boxes (bodies are built with it: new_contact_body(..., next=)).
      integer :: next = default_next
      !> N_box: scan points over the polar range pi (2 N_box over the azimuth range), i.e. scan
      !> spacing pi/N_box rad; only patches the certified bounds leave undecided are scanned.
      integer :: nbox = 128
      !> Certified mode: "no contact" guaranteed (patch bounds, subdivision to `resolution`).
      logical :: certified = .false.
      !> Certified mode: relative gap resolution. Contact may be reported for bodies that do not
      !> overlap only when their surfaces are closer than gap x L, L = min over the two bodies of
      !> scale x the largest edge of the certified body-frame extent box (about the particle length).
      real(wp) :: gap = 1.0e-3_wp
      !> Certified mode: patch size (radians) at which an undecided patch is reported as contact
      !> whatever its gap (a safety floor for the subdivision).
      real(wp) :: resolution = pi / 65536.0_wp
      !> Newton-Raphson: number of fixed phi_1 values.
      integer :: nr_lines = 36
      !> Newton-Raphson: starting theta_1 values per line.
      integer :: nr_starts = 6
      !> Newton-Raphson: iterations per start.
      integer :: nr_iterations = 30
   end type contact_params_type

   !> A relative pose: y_B = m y_A + t; world x = cw + rw y_A; q = B's centre in A's frame.
   type :: pose_type
      real(wp) :: m(3, 3) = 0.0_wp
      real(wp) :: t(3) = 0.0_wp
      real(wp) :: q(3) = 0.0_wp
      real(wp) :: k = 1.0_wp
      real(wp) :: rw(3, 3) = 0.0_wp
      real(wp) :: cw(3) = 0.0_wp
      real(wp) :: sb = 1.0_wp
   end type pose_type

   !> Fixed data of a box traversal: A-to-B rotation, world scales of the body frames, the box.
   type :: traversal_type
      real(wp) :: rot(3, 3) = 0.0_wp
      real(wp) :: sa = 1.0_wp, sb = 1.0_wp
      real(wp) :: lo(3) = 0.0_wp, hi(3) = 0.0_wp
   end type traversal_type

   !> What the box traversal needs to test A's leaf patches against B (`probe_patch`).
   type :: probe_type
      type(contact_params_type) :: params
      real(wp) :: eob_lo(3) = 0.0_wp, eob_hi(3) = 0.0_wp, cbox_lo(3) = 0.0_wp, cbox_hi(3) = 0.0_wp
      !> Certified mode: radial gap tolerance in B units and in A units.
      real(wp) :: tol = 0.0_wp, tol_a = 0.0_wp
      integer :: stop_level = stored_level
   end type probe_type

   !> A's patch in a box traversal: level, row, column, storage index; its box (centre, axes,
   !> half-extents, containing-ball radius) in B's frame; the cone from B's centre holding the
   !> ball (`cone` false when the ball holds B's centre).
   type :: a_node_type
      integer :: l, i, j, k
      real(wp) :: c(3), e(3, 3), h(3), r
      real(wp) :: u(3), sinb, cosb
      logical :: cone
   end type a_node_type

   !> B's patch in a box traversal: level, row, column, storage index; the cone from A's centre
   !> (A's frame) holding its box's ball.
   type :: b_node_type
      integer :: l, i, j, k
      real(wp) :: u(3), sinb, cosb
      logical :: cone
   end type b_node_type

   integer, parameter :: code_none = -1, code_outside = 0, code_inside = 1, code_mixed = 2
   !> Answers of `cap_bounds` for its callers: the radial range lies beyond the surface over the whole
   !> cap (outside), or below it (inside); any other answer decides nothing.
   integer, parameter :: cap_outside = code_outside, cap_inside = code_inside
   !> Largest number of probed leaf patches of A remembered by the box traversal.
   integer, parameter :: max_leaves = 256
   !> Outcome of the box traversal: no contact (certain), contact found, undecided.
   integer, parameter :: sep_disjoint = 0, sep_found = 1, sep_unsure = 2
   !> Finest patch level of the wall test (pi/1024 rad; levels beyond stored_level use local bounds).
   integer, parameter :: wall_level = stored_level + 2


   !> Outcomes of the first stages (`early_stages`).
   integer, parameter :: early_open = 0, early_overlap = 1, early_disjoint = 2
   !> Steps of the separating-plane search of stage 2c.
   integer, parameter :: plane_steps = 6

   !> What the first stages decided, and the gap tolerance of the later ones (mm).
   type :: early_type
      integer :: status = early_open
      real(wp) :: tol = 0.0_wp
   end type early_type

   !> Pair visits, and pairs waiting in its heap, after which the distance test
   !> (`surfaces_within`) stops and reports the pair as too close (safety floors never reached in
   !> our tests, like `resolution`; the heap's bound keeps its memory below about 8 MB).
   integer, parameter :: max_within_visits = 200000, max_within_heap = 16384
   !> Steps (each body's point moved once) of the local descent of `near_points`.
   integer, parameter :: near_steps = 8

   !> A piece of a body in the distance test (`surfaces_within`): the whole body (level -1) or
   !> patch (l, i, j); its radial bounds (its own shape units, for its children); its bounding
   !> ball (centre c, radius rho), its surface point at the cap centre (`sample`, not for a whole
   !> body) and its oriented box (centre, axes, half-extents, radius of a ball about the centre
   !> that holds the piece), all in B's frame and units.
   type :: w_node_type
      integer :: l = -1, i = 0, j = 0
      real(wp) :: rlo = 0.0_wp, rhi = 0.0_wp
      real(wp) :: c(3) = 0.0_wp, rho = 0.0_wp, p(3) = 0.0_wp
      logical :: sample = .false.
      real(wp) :: bc(3) = 0.0_wp, be(3, 3) = 0.0_wp, bh(3) = 0.0_wp, br = 0.0_wp
   end type w_node_type

   !> Fixed data of the distance test: the poses, the A-to-B rotation, the world scales, the
   !> world boxes that hold the parts of A (alo, ahi) and of B (blo, bhi) that can come within m
   !> of the other body, the margin and the margin plus tolerance in B units, the finest level.
   type :: w_frame_type
      type(pose_type) :: pab, pba
      real(wp) :: rot(3, 3) = 0.0_wp
      real(wp) :: wsa = 1.0_wp, wsb = 1.0_wp
      real(wp) :: alo(3) = 0.0_wp, ahi(3) = 0.0_wp, blo(3) = 0.0_wp, bhi(3) = 0.0_wp
      real(wp) :: m = 0.0_wp, mtol = 0.0_wp
      integer :: stop_level = stored_level
   end type w_frame_type
contains

   !> True when the first stages of `bodies_overlap` alone prove that the two posed bodies
   !> overlap (`first_stages`). When it is true, `bodies_overlap` is true; when it is false,
   !> nothing is known. A candidate tested against several bodies can look for such an overlap
   !> among all of them before it certifies any pair near contact (`packing%fits`).
   pure logical function overlap_early(body_a, center_a, rot_a, scale_a, body_b, center_b, rot_b, scale_b, &
                                       params, margin) result(hit)
      !> First body.
      type(contact_body_type), intent(in) :: body_a
      !> Its centre (world, mm).
      real(wp), intent(in) :: center_a(3)
      !> Its rotation, body to world.
      real(wp), intent(in) :: rot_a(3, 3)
      !> Its scale (mm per shape unit).
      real(wp), intent(in) :: scale_a
      !> Second body.
      type(contact_body_type), intent(in) :: body_b
      !> Its centre.
      real(wp), intent(in) :: center_b(3)
      !> Its rotation.
      real(wp), intent(in) :: rot_b(3, 3)
      !> Its scale.
      real(wp), intent(in) :: scale_b
      !> Parameters.
      type(contact_params_type), intent(in) :: params
      !> Gap (mm) the bodies must keep, as in `bodies_overlap` (default 0).
      real(wp), intent(in), optional :: margin
      logical :: apart
      call first_stages(body_a, center_a, rot_a, scale_a, body_b, center_b, rot_b, scale_b, params, hit, apart, &
                        margin)
   end function overlap_early

   !> The first stages of `bodies_overlap` alone (bounding and inscribed spheres, the surface
   !> points on the line of centres, the furthest-reaching points of the support tables; in
   !> certified mode or with a margin also the separating planes of 2c and the local descent of
   !> 2d): a few dozen radius evaluations, no box traversal or distance search. `hit`: they proved
   !> an overlap (closer than the margin), and `bodies_overlap` is true; `apart`: they proved the
   !> bodies apart, and it is false; neither: nothing is known.
   pure subroutine first_stages(body_a, center_a, rot_a, scale_a, body_b, center_b, rot_b, scale_b, params, hit, &
                                apart, margin)
      !> The posed bodies and the parameters, as in `overlap_early`.
      type(contact_body_type), intent(in) :: body_a, body_b
      real(wp), intent(in) :: center_a(3), rot_a(3, 3), scale_a, center_b(3), rot_b(3, 3), scale_b
      type(contact_params_type), intent(in) :: params
      !> Overlap proved; bodies proved apart.
      logical, intent(out) :: hit, apart
      !> Gap (mm) the bodies must keep, as in `bodies_overlap` (default 0).
      real(wp), intent(in), optional :: margin
      type(early_type) :: e
      real(wp) :: m
      m = 0.0_wp
      if (present(margin)) m = max(0.0_wp, margin)
      ! with a margin or in certified mode, the separating planes too, then a local descent (a
      ! pair near contact otherwise goes to the box traversal or the distance search)
      call early_stages(body_a, center_a, rot_a, scale_a, body_b, center_b, rot_b, scale_b, params, .true., &
                        m > 0.0_wp .or. params%certified, m, e)
      hit = e%status == early_overlap
      apart = e%status == early_disjoint
      if (e%status /= early_open) return
      if (m > 0.0_wp) then
         hit = near_points(body_a, center_a, rot_a, scale_a, body_b, center_b, rot_b, scale_b, m)
      else if (params%certified .and. params%method /= contact_method%newton_raphson) then
         hit = inside_points(body_a, center_a, rot_a, scale_a, body_b, center_b, rot_b, scale_b)
      end if
   end subroutine first_stages

   !> Stages 1 to 2c of `bodies_overlap` (with the Newton-Raphson method stage 1 only; 2 and 2b
   !> only with `proofs`, 2c only with `planes`): e%status says whether they decide the pair;
   !> e%tol is the gap tolerance of the later stages. With a margin m > 0 (mm) every stage asks
   !> whether the bodies come closer than m: the separations must exceed m, and the proofs show
   !> points of the two bodies closer than m (the Newton-Raphson method is not used then).
   pure subroutine early_stages(body_a, center_a, rot_a, scale_a, body_b, center_b, rot_b, scale_b, params, proofs, &
                                planes, m, e)
      type(contact_body_type), intent(in) :: body_a, body_b
      real(wp), intent(in) :: center_a(3), rot_a(3, 3), scale_a, center_b(3), rot_b(3, 3), scale_b
      type(contact_params_type), intent(in) :: params
      !> Whether to run the overlap proofs of stages 2 and 2b (false: the caller ran them already).
      logical, intent(in) :: proofs
      !> Whether to search separating planes off the line of centres (stage 2c).
      logical, intent(in) :: planes
      !> Margin (mm, >= 0).
      real(wp), intent(in) :: m
      type(early_type), intent(out) :: e
      real(wp) :: dvec(3), dist, u(3), ra, rb, va(3), vb(3), hsum
      integer :: ka, kb
      logical :: tables
      dvec = center_b - center_a
      dist = sqrt(sum(dvec**2))
      ! stage 1: bounding and inscribed spheres
      if (dist >= scale_a * body_a%r_max + scale_b * body_b%r_max + m) then
         e%status = early_disjoint
         return
      end if
      if (dist < scale_a * body_a%r_min + scale_b * body_b%r_min + m) then
         e%status = early_overlap
         return
      end if
      if (params%method == contact_method%newton_raphson .and. m <= 0.0_wp) return
      u = dvec / dist
      va = matmul(u, rot_a)
      vb = -matmul(u, rot_b)
      e%tol = params%gap * min(scale_a * maxval(body_a%box_hi - body_a%box_lo), &
                               scale_b * maxval(body_b%box_hi - body_b%box_lo))
      ! stage 1b: support functions along the line of centres (certified tables): a plane normal
      ! to u separates the bodies by more than the gap tolerance, so no later stage could report
      ! contact (certified mode reports gaps below tol)
      tables = allocated(body_a%supp) .and. allocated(body_b%supp)
      if (tables) then
         ka = support_cell(va)
         kb = support_cell(vb)
         hsum = scale_a * support_bound(body_a, va, ka) + scale_b * support_bound(body_b, vb, kb)
         if (hsum + e%tol + m < dist) then
            e%status = early_disjoint
            return
         end if
      end if
      if (proofs) then
         ! stage 2: line of centres
         ra = scale_a * body_a%shape%radius_dir(va)
         rb = scale_b * body_b%shape%radius_dir(vb)
         if (ra + rb + m > dist) then
            e%status = early_overlap
            return
         end if
         ! stage 2b (certified mode, which reports every true overlap): the surface points of A and
         ! of B that reach furthest towards the other body (support tables), each tested against
         ! the other body along the ray to its centre
         if ((params%certified .or. m > 0.0_wp) .and. tables) then
            if (reach_inside(body_a, center_a, rot_a, scale_a, ka, body_b, center_b, rot_b, scale_b, m) .or. &
                reach_inside(body_b, center_b, rot_b, scale_b, kb, body_a, center_a, rot_a, scale_a, m)) then
               e%status = early_overlap
               return
            end if
         end if
      end if
      ! stage 2c: separating planes of other normals than the line of centres (support tables)
      if (planes .and. tables) then
         if (plane_found(body_a, rot_a, scale_a, body_b, rot_b, scale_b, dvec, u, ka, kb, dist - hsum, e%tol + m)) &
            e%status = early_disjoint
      end if
   end subroutine early_stages

   !> Stage 2c: a plane that separates the bodies by more than tol, searched from the line of
   !> centres (unit u, the cells ka and kb and the separation bound sep of stage 1b) by
   !> `plane_steps` steps of projected gradient ascent of the tables' separation bound
   !> s(n) = n . d - s_A h_A(n) - s_B h_B(-n) (d the centre vector, h the tables' certified bounds
   !> of the support functions). Its gradient is about the
   !> difference of the two support points (the cells' stored points); the step starts at 1/|d|,
   !> grows by half after a better normal and halves after a worse one. A plane found separates
   !> the convex hulls, hence the bodies, by more than tol: "no contact" is then what every later
   !> stage answers (certified mode reports contact only for gaps below tol). Non-convex bodies
   !> whose hulls meet are left to the later stages.
   pure logical function plane_found(a, ra, sa, b, rb, sb, dvec, u, ka, kb, sep, tol) result(found)
      type(contact_body_type), intent(in) :: a, b
      real(wp), intent(in) :: ra(3, 3), sa, rb(3, 3), sb, dvec(3), u(3), sep, tol
      integer, intent(in) :: ka, kb
      real(wp) :: n(3), nt(3), g(3), pa(3), pb(3), va(3), vb(3), best, s, alpha
      integer :: i, ca, cb
      found = .true.
      n = u
      best = sep
      pa = sa * matmul(ra, real(a%supp(1:3, ka), wp))
      pb = dvec + sb * matmul(rb, real(b%supp(1:3, kb), wp))
      alpha = 1.0_wp / norm2(dvec)
      do i = 1, plane_steps
         g = pb - pa
         g = g - dot_product(g, n) * n
         nt = n + alpha * g
         nt = nt / norm2(nt)
         va = matmul(nt, ra)
         vb = -matmul(nt, rb)
         ca = support_cell(va)
         cb = support_cell(vb)
         s = dot_product(nt, dvec) - sa * support_bound(a, va, ca) - sb * support_bound(b, vb, cb)
         if (s > tol) return
         if (s > best) then
            n = nt
            best = s
            pa = sa * matmul(ra, real(a%supp(1:3, ca), wp))
            pb = dvec + sb * matmul(rb, real(b%supp(1:3, cb), wp))
            alpha = 1.5_wp * alpha
         else
            alpha = 0.5_wp * alpha
         end if
      end do
      found = .false.
   end function plane_found

   !> True when the two posed bodies overlap (thread-safe, no allocation).
   pure logical function bodies_overlap(body_a, center_a, rot_a, scale_a, body_b, center_b, rot_b, scale_b, &
                                        params, proofs_done, margin) result(hit)
      !> First body.
      type(contact_body_type), intent(in) :: body_a
      !> Its centre (world, mm).
      real(wp), intent(in) :: center_a(3)
      !> Its rotation, body to world.
      real(wp), intent(in) :: rot_a(3, 3)
      !> Its scale (mm per shape unit).
      real(wp), intent(in) :: scale_a
      !> Second body.
      type(contact_body_type), intent(in) :: body_b
      !> Its centre.
      real(wp), intent(in) :: center_b(3)
      !> Its rotation.
      real(wp), intent(in) :: rot_b(3, 3)
      !> Its scale.
      real(wp), intent(in) :: scale_b
      !> Parameters.
      type(contact_params_type), intent(in) :: params
      !> The caller ran `overlap_early` on this very pair and it proved no overlap: its overlap
      !> proofs (line of centres, support reach) are not evaluated again (default false).
      logical, intent(in), optional :: proofs_done
      !> Gap (mm) the bodies must keep (default 0): with m > 0 the answer is whether the bodies
      !> come closer than m (Euclidean distance between their closest points), by the certified
      !> distance test whatever the method (`surfaces_within`'s tolerance: pairs whose gap lies in
      !> [m, m + tol] may be reported too). Exclusion shells of thickness t are tested so, on the
      !> bare bodies, with m = t_a + t_b.
      real(wp), intent(in), optional :: margin
      real(wp) :: eob_lo(3), eob_hi(3), cbox_lo(3), cbox_hi(3), tol, m
      logical :: proofs
      type(pose_type) :: pab, pba
      logical :: found, certain
      type(probe_type) :: pr
      type(early_type) :: e
      integer :: status

      proofs = .true.
      if (present(proofs_done)) proofs = .not. proofs_done
      m = 0.0_wp
      if (present(margin)) m = max(0.0_wp, margin)
      call early_stages(body_a, center_a, rot_a, scale_a, body_b, center_b, rot_b, scale_b, params, proofs, .true., &
                        m, e)
      select case (e%status)
      case (early_overlap)
         hit = .true.
         return
      case (early_disjoint)
         hit = .false.
         return
      end select
      if (m > 0.0_wp) then
         hit = .true.
         if (proofs) then
            if (near_points(body_a, center_a, rot_a, scale_a, body_b, center_b, rot_b, scale_b, m)) return
         end if
         hit = surfaces_within(body_a, center_a, rot_a, scale_a, body_b, center_b, rot_b, scale_b, m, e%tol, params)
         return
      end if
      if (params%method == contact_method%newton_raphson) then
         hit = nr_overlap(body_a, center_a, rot_a, scale_a, body_b, center_b, rot_b, scale_b, params)
         return
      end if
      ! stage 2d without a margin (certified mode, which reports every true overlap): a surface
      ! point of one body found inside the other by a short descent
      if (proofs .and. params%certified) then
         hit = .true.
         if (inside_points(body_a, center_a, rot_a, scale_a, body_b, center_b, rot_b, scale_b)) return
      end if
      tol = e%tol
      ! stage 3: extent boxes and the EOB
      call eob_box(body_a, center_a, rot_a, scale_a, body_b, center_b, rot_b, scale_b, params%certified, &
                   eob_lo, eob_hi)
      if (any(eob_lo > eob_hi)) then
         hit = .false.
         return
      end if
      ! stage 4: surface of A against B, then (unless A's surface was proven outside B) surface of
      ! B against A
      call eob_box(body_a, center_a, rot_a, scale_a, body_b, center_b, rot_b, scale_b, .true., cbox_lo, cbox_hi)
      pab = make_pose(center_a, rot_a, scale_a, center_b, rot_b, scale_b)
      pba = make_pose(center_b, rot_b, scale_b, center_a, rot_a, scale_a)
      hit = .true.
      ! stage 4a: the surfaces' box hierarchies traversed together inside the certified EOB; each
      ! leaf patch of A left in an unseparated pair is tested against B at once
      pr%params = params
      pr%eob_lo = eob_lo
      pr%eob_hi = eob_hi
      pr%cbox_lo = cbox_lo
      pr%cbox_hi = cbox_hi
      pr%tol = tol / scale_b
      pr%tol_a = tol / scale_a
      pr%stop_level = stop_level(params)
      call separate_surfaces(body_a, body_b, pab, pba, pr, status)
      if (status == sep_found) return
      if (status == sep_disjoint) then
         hit = .false.
         return
      end if
      ! stage 4b: surface of A against B, then (unless A's surface was proven outside B) surface
      ! of B against A
      call probe_surface(body_a, body_b, pab, eob_lo, eob_hi, cbox_lo, cbox_hi, params, tol / scale_b, found, &
                         certain)
      if (found) return
      ! A's surface certainly outside B: B is then inside A or disjoint from it, and B inside A
      ! would put B's centre inside A (deeper than scale_b r_min of B), which stage 2 reports
      if (certain) then
         hit = .false.
         return
      end if
      call probe_surface(body_b, body_a, pba, eob_lo, eob_hi, cbox_lo, cbox_hi, params, tol / scale_a, found, &
                         certain)
      if (found) return
      hit = .false.
   end function bodies_overlap


   !> Whether two posed bodies come closer than m (mm) (stage 4 of `bodies_overlap` with a
   !> margin). The two surfaces are searched together, piece against piece, from the whole bodies
   !> down (`search_within`, best first): a pair of pieces is dropped when their bounding balls
   !> are further apart than m, or when a lower bound of the distance between their oriented
   !> boxes exceeds m (`box_gap`; stored certified boxes down to leaf_level, thin boxes from the
   !> local Taylor bounds below it, `w_node`), or when a piece lies outside the world region
   !> where it could come within m of the other body; it proves the bodies closer than m + tol
   !> when its two surface points (cap centres) are; otherwise the larger piece is split. A pair
   !> still undecided when both pieces have reached the resolution of certified mode, or after
   !> `max_within_visits` pairs (`max_within_heap` waiting), is reported too. So "false" is
   !> certain (bodies at least m apart, up to rounding); "true" means closer than m + tol, except
   !> at those safety floors (the finest pieces are about r pi/65536, far below tol). Bodies that
   !> overlap have crossing surfaces, or one holds the other's centre, which the first stages
   !> report.
   pure logical function surfaces_within(a, ca, ra, sa, b, cb, rb, sb, m, tol, params) result(hit)
      type(contact_body_type), intent(in) :: a, b
      real(wp), intent(in) :: ca(3), ra(3, 3), sa, cb(3), rb(3, 3), sb, m, tol
      type(contact_params_type), intent(in) :: params
      type(w_frame_type) :: f
      type(contact_params_type) :: q
      type(w_node_type) :: na, nb
      real(wp) :: xlo(3), xhi(3), ylo(3), yhi(3)
      integer :: visits
      hit = .false.
      call world_box(a%box_lo, a%box_hi, ca, ra, sa, xlo, xhi)
      call world_box(b%box_lo, b%box_hi, cb, rb, sb, ylo, yhi)
      f%alo = max(xlo, ylo - m)
      f%ahi = min(xhi, yhi + m)
      f%blo = max(ylo, xlo - m)
      f%bhi = min(yhi, xhi + m)
      if (any(f%alo > f%ahi) .or. any(f%blo > f%bhi)) return
      f%pab = make_pose(ca, ra, sa, cb, rb, sb)
      f%pba = make_pose(cb, rb, sb, ca, ra, sa)
      f%rot = f%pab%m / f%pab%k
      f%wsa = sa
      f%wsb = sb
      f%m = m / sb
      f%mtol = (m + tol) / sb
      q = params
      q%certified = .true.
      f%stop_level = stop_level(q)
      ! the whole bodies: bounding spheres and certified boxes
      na%rho = f%pab%k * a%r_max * (1.0_wp + 1.0e-12_wp)
      na%c = f%pab%t
      na%rlo = a%r_min
      na%rhi = a%r_max
      na%bc = matmul(f%pab%m, 0.5_wp * (a%box_lo + a%box_hi)) + f%pab%t
      na%be = f%rot
      na%bh = f%pab%k * 0.5_wp * (a%box_hi - a%box_lo)
      na%br = norm2(na%bh) * (1.0_wp + 1.0e-12_wp)
      nb%rho = b%r_max
      nb%rlo = b%r_min
      nb%rhi = b%r_max
      nb%bc = 0.5_wp * (b%box_lo + b%box_hi)
      nb%be = reshape([1.0_wp, 0.0_wp, 0.0_wp, 0.0_wp, 1.0_wp, 0.0_wp, 0.0_wp, 0.0_wp, 1.0_wp], [3, 3])
      nb%bh = 0.5_wp * (b%box_hi - b%box_lo)
      nb%br = norm2(nb%bh) * (1.0_wp + 1.0e-12_wp)
      visits = 0
      call search_within(a, b, f, na, nb, visits, hit)
   end function surfaces_within


   !> Whether a short local descent finds two surface points, one of each posed body, closer than
   !> m (mm): from the surface points on the line of centres, each body's point in turn moves to
   !> the surface point under the projection of the other body's point onto its tangent plane
   !> (`surface_step`), `near_steps` times or until the distance stops falling. True only with
   !> such a pair found, which proves the bodies closer than m (the certified distance search
   !> would answer true too: its pieces holding those points are within m); false says nothing.
   !> A cheap proof for pairs near contact, before `surfaces_within`.
   pure logical function near_points(a, ca, ra, sa, b, cb, rb, sb, m) result(hit)
      type(contact_body_type), intent(in) :: a, b
      real(wp), intent(in) :: ca(3), ra(3, 3), sa, cb(3), rb(3, 3), sb, m
      real(wp) :: u(3), pa(3), pb(3), na(3), nb(3), d, dnew, lim
      integer :: k
      hit = .false.
      u = cb - ca
      d = norm2(u)
      if (d <= 0.0_wp) return
      u = u / d
      call surface_at(a, ca, ra, sa, matmul(u, ra), pa, na)
      call surface_at(b, cb, rb, sb, -matmul(u, rb), pb, nb)
      ! the points are the surfaces' to rounding (about 1e-15 of their size)
      lim = m * (1.0_wp - 1.0e-9_wp)
      d = norm2(pa - pb)
      do k = 1, near_steps
         if (d < lim) then
            hit = .true.
            return
         end if
         call surface_at(b, cb, rb, sb, matmul(tangent_foot(pa, pb, nb) - cb, rb), pb, nb)
         call surface_at(a, ca, ra, sa, matmul(tangent_foot(pb, pa, na) - ca, ra), pa, na)
         dnew = norm2(pa - pb)
         if (dnew > d * (1.0_wp - 1.0e-3_wp)) then
            hit = dnew < lim
            return
         end if
         d = dnew
      end do
      hit = d < lim
   contains
      !> The projection of t onto the plane through p with unit normal n.
      pure function tangent_foot(t, p, n) result(q)
         real(wp), intent(in) :: t(3), p(3), n(3)
         real(wp) :: q(3)
         q = t - dot_product(t - p, n) * n
      end function tangent_foot
   end function near_points

   !> Whether a short descent finds a surface point of one posed body strictly inside the other
   !> (`dives_into`, A's point into B, then B's into A). True only with such a point found, which
   !> proves an overlap (certified mode reports it too); false says nothing.
   pure logical function inside_points(a, ca, ra, sa, b, cb, rb, sb) result(hit)
      type(contact_body_type), intent(in) :: a, b
      real(wp), intent(in) :: ca(3), ra(3, 3), sa, cb(3), rb(3, 3), sb
      hit = dives_into(a, ca, ra, sa, b, cb, rb, sb)
      if (.not. hit) hit = dives_into(b, cb, rb, sb, a, ca, ra, sa)
   end function inside_points

   !> A's surface point on the line of centres moved downhill of its radial gap to B,
   !> h(p) = |p - c_B| - s_B r_B(direction), along A's tangent plane (a Newton step aimed at -h,
   !> halved when h does not fall), `near_steps` times: true when a point with h below
   !> -1e-9 s_B r_max,B is found (a point of A inside B: the bodies overlap).
   pure logical function dives_into(a, ca, ra, sa, b, cb, rb, sb) result(hit)
      type(contact_body_type), intent(in) :: a, b
      real(wp), intent(in) :: ca(3), ra(3, 3), sa, cb(3), rb(3, 3), sb
      real(wp) :: u(3), p(3), n(3), h, dh(3), t(3), q(3), nq(3), hq, dq(3), lim, tt, step
      integer :: k, tries
      logical :: ok
      hit = .false.
      u = cb - ca
      if (norm2(u) <= 0.0_wp) return
      call surface_at(a, ca, ra, sa, matmul(u, ra), p, n)
      call radial_gap_at(b, cb, rb, sb, p, h, dh, ok)
      if (.not. ok) return
      lim = -1.0e-9_wp * sb * b%r_max
      do k = 1, near_steps
         if (h < lim) then
            hit = .true.
            return
         end if
         t = dh - dot_product(dh, n) * n
         tt = dot_product(t, t)
         if (tt <= 1.0e-24_wp) return
         step = 2.0_wp * h / tt
         do tries = 1, 3
            call surface_at(a, ca, ra, sa, matmul(p - step * t - ca, ra), q, nq)
            call radial_gap_at(b, cb, rb, sb, q, hq, dq, ok)
            if (ok .and. hq < h) exit
            step = 0.5_wp * step
         end do
         if (.not. ok .or. hq >= h) return
         p = q
         n = nq
         h = hq
         dh = dq
      end do
      hit = h < lim
   end function dives_into

   !> The radial gap h = |p - c_B| - s_B r_B(v) of a world point p to posed body B along the ray
   !> from B's centre, and its gradient (world): v - s_B g/|p - c_B| with g B's surface gradient
   !> in the world frame. `ok` false when the ray is within 1e-6 rad of B's z axis (not evaluated).
   pure subroutine radial_gap_at(b, cb, rb, sb, p, h, dh, ok)
      type(contact_body_type), intent(in) :: b
      real(wp), intent(in) :: cb(3), rb(3, 3), sb, p(3)
      real(wp), intent(out) :: h, dh(3)
      logical, intent(out) :: ok
      real(wp) :: x(3), rho, v(3), w(3), r, g(3)
      x = p - cb
      rho = norm2(x)
      h = huge(1.0_wp)
      dh = 0.0_wp
      ok = rho > 0.0_wp
      if (.not. ok) return
      v = x / rho
      w = matmul(v, rb)
      ok = w(1)**2 + w(2)**2 >= 1.0e-12_wp
      if (.not. ok) return
      call b%shape%radius_gradient(w, r, g)
      h = rho - sb * r
      dh = v - sb * matmul(rb, g) / rho
   end subroutine radial_gap_at

   !> The surface point p (world) of body x posed at (cx, rx, sx) along the body-frame direction v
   !> (need not be normalised; moved off the z axis when within 1e-6 rad of it), and the unit
   !> outward normal n there.
   pure subroutine surface_at(x, cx, rx, sx, v, p, n)
      type(contact_body_type), intent(in) :: x
      real(wp), intent(in) :: cx(3), rx(3, 3), sx, v(3)
      real(wp), intent(out) :: p(3), n(3)
      real(wp) :: w(3), r, g(3), len
      len = norm2(v)
      if (len > 0.0_wp) then
         w = v / len
      else
         w = [1.0_wp, 0.0_wp, 0.0_wp]
      end if
      if (w(1)**2 + w(2)**2 < 1.0e-12_wp) then
         w(1) = w(1) + 1.0e-6_wp
         w = w / norm2(w)
      end if
      call x%shape%radius_gradient(w, r, g)
      p = cx + sx * matmul(rx, r * w)
      n = matmul(rx, r * w - g)
      n = n / norm2(n)
   end subroutine surface_at

   !> A lower bound of the distance between two oriented boxes (centre, orthonormal axes as
   !> columns, half-extents): the largest separation of their projections on the line of centres
   !> and on the six box axes (each is a lower bound of the Euclidean distance), rounded down.
   pure real(wp) function box_gap(c1, e1, h1, c2, e2, h2) result(gap)
      real(wp), intent(in) :: c1(3), e1(3, 3), h1(3), c2(3), e2(3, 3), h2(3)
      real(wp) :: d(3), dn, l(3), s
      integer :: k
      d = c2 - c1
      dn = norm2(d)
      gap = -huge(1.0_wp)
      if (dn > 0.0_wp) then
         l = d / dn
         gap = dn - proj(e1, h1, l) - proj(e2, h2, l)
      end if
      do k = 1, 3
         s = abs(dot_product(d, e1(:, k))) - h1(k) - proj(e2, h2, e1(:, k))
         gap = max(gap, s)
         s = abs(dot_product(d, e2(:, k))) - h2(k) - proj(e1, h1, e2(:, k))
         gap = max(gap, s)
      end do
      gap = gap - 1.0e-12_wp * (dn + sum(h1) + sum(h2))
   contains
      pure real(wp) function proj(e, h, v) result(p)
         real(wp), intent(in) :: e(3, 3), h(3), v(3)
         p = h(1) * abs(dot_product(e(:, 1), v)) + h(2) * abs(dot_product(e(:, 2), v)) &
             + h(3) * abs(dot_product(e(:, 3), v))
      end function proj
   end function box_gap

   !> The search of `surfaces_within`, best first: pairs of pieces wait in a heap ordered by the
   !> lower bound of their distance (`box_gap`); the nearest pair is taken, its larger piece split,
   !> and the children that can still come within m of the other piece go back into the heap. A
   !> pair whose two surface points are closer than m + tol ends the search (hit); so does a pair
   !> left undecided at the finest level, or running out of `max_within_visits`. An empty heap
   !> means no pair of pieces comes within m.
   pure subroutine search_within(a, b, f, root_a, root_b, visits, hit)
      type(contact_body_type), intent(in) :: a, b
      type(w_frame_type), intent(in) :: f
      type(w_node_type), intent(in) :: root_a, root_b
      integer, intent(inout) :: visits
      logical, intent(inout) :: hit
      type(w_node_type), allocatable :: ha(:), hb(:)
      real(wp), allocatable :: hk(:)
      type(w_node_type) :: na, nb, kid
      integer :: nh, n, nch, ic, jc
      logical :: split_a, live
      allocate (ha(32), hb(32), hk(32))
      nh = 0
      call heap_push(ha, hb, hk, nh, root_a, root_b, 0.0_wp)
      do while (nh > 0)
         call heap_pop(ha, hb, hk, nh, na, nb)
         visits = visits + 1
         if (visits > max_within_visits) then
            hit = .true.
            return
         end if
         if (na%l < f%stop_level .and. (na%rho >= nb%rho .or. nb%l >= f%stop_level)) then
            split_a = .true.
            nch = merge(patch_rows(0) * patch_cols(0), 4, na%l < 0)
         else if (nb%l < f%stop_level) then
            split_a = .false.
            nch = merge(patch_rows(0) * patch_cols(0), 4, nb%l < 0)
         else
            hit = .true.
            return
         end if
         do n = 0, nch - 1
            if (split_a) then
               call child_of(na, n, ic, jc)
               call w_node(a, f, .true., na%l + 1, ic, jc, na%rlo, na%rhi, nb, kid, live)
               if (live) call consider(kid, nb, f, ha, hb, hk, nh, hit)
            else
               call child_of(nb, n, ic, jc)
               call w_node(b, f, .false., nb%l + 1, ic, jc, nb%rlo, nb%rhi, na, kid, live)
               if (live) call consider(na, kid, f, ha, hb, hk, nh, hit)
            end if
            if (hit) return
         end do
      end do
   contains
      pure subroutine child_of(nd, k, i, j)
         type(w_node_type), intent(in) :: nd
         integer, intent(in) :: k
         integer, intent(out) :: i, j
         if (nd%l < 0) then
            i = mod(k, patch_rows(0)) + 1
            j = k / patch_rows(0) + 1
         else
            i = 2 * nd%i - 1 + mod(k, 2)
            j = 2 * nd%j - 1 + k / 2
         end if
      end subroutine child_of
   end subroutine search_within

   !> A pair of pieces whose balls `w_node` found within m of each other: dropped when their boxes
   !> are apart by more than m, a witness, or into the heap (hit when the heap is full:
   !> `max_within_heap`).
   pure subroutine consider(x, y, f, ha, hb, hk, nh, hit)
      type(w_node_type), intent(in) :: x, y
      type(w_frame_type), intent(in) :: f
      type(w_node_type), allocatable, intent(inout) :: ha(:), hb(:)
      real(wp), allocatable, intent(inout) :: hk(:)
      integer, intent(inout) :: nh
      logical, intent(inout) :: hit
      real(wp) :: key
      key = box_gap(x%bc, x%be, x%bh, y%bc, y%be, y%bh)
      if (key > f%m) return
      if (x%sample .and. y%sample) then
         if (sum((x%p - y%p)**2) <= f%mtol**2) then
            hit = .true.
            return
         end if
      end if
      if (nh >= max_within_heap) then
         hit = .true.
         return
      end if
      call heap_push(ha, hb, hk, nh, x, y, key)
   end subroutine consider

   !> Into the heap of `search_within` (grown when full).
   pure subroutine heap_push(ha, hb, hk, nh, x, y, key)
      type(w_node_type), allocatable, intent(inout) :: ha(:), hb(:)
      real(wp), allocatable, intent(inout) :: hk(:)
      integer, intent(inout) :: nh
      type(w_node_type), intent(in) :: x, y
      real(wp), intent(in) :: key
      integer :: i, p
      type(w_node_type), allocatable :: ta(:), tb(:)
      real(wp), allocatable :: tk(:)
      if (nh == size(hk)) then
         allocate (ta(2 * nh), tb(2 * nh), tk(2 * nh))
         ta(1:nh) = ha(1:nh)
         tb(1:nh) = hb(1:nh)
         tk(1:nh) = hk(1:nh)
         call move_alloc(ta, ha)
         call move_alloc(tb, hb)
         call move_alloc(tk, hk)
      end if
      nh = nh + 1
      i = nh
      do while (i > 1)
         p = i / 2
         if (hk(p) <= key) exit
         ha(i) = ha(p)
         hb(i) = hb(p)
         hk(i) = hk(p)
         i = p
      end do
      ha(i) = x
      hb(i) = y
      hk(i) = key
   end subroutine heap_push

   !> The pair with the smallest key out of the heap of `search_within`.
   pure subroutine heap_pop(ha, hb, hk, nh, x, y)
      type(w_node_type), intent(inout) :: ha(:), hb(:)
      real(wp), intent(inout) :: hk(:)
      integer, intent(inout) :: nh
      type(w_node_type), intent(out) :: x, y
      integer :: i, c
      real(wp) :: key
      type(w_node_type) :: la, lb
      x = ha(1)
      y = hb(1)
      la = ha(nh)
      lb = hb(nh)
      key = hk(nh)
      nh = nh - 1
      if (nh == 0) return
      i = 1
      do
         c = 2 * i
         if (c > nh) exit
         if (c < nh) then
            if (hk(c + 1) < hk(c)) c = c + 1
         end if
         if (key <= hk(c)) exit
         ha(i) = ha(c)
         hb(i) = hb(c)
         hk(i) = hk(c)
         i = c
      end do
      ha(i) = la
      hb(i) = lb
      hk(i) = key
   end subroutine heap_pop

   !> Piece (l, i, j) of body x (A when is_a, else B) for `search_within`, in B's frame; `live`
   !> false when its bounding ball misses the world region of that body in the frame `f`, or lies
   !> further than m from the ball of the other piece `other` (both tested on the sector ball of
   !> the cap and its radial bounds, before the expansion is evaluated). Levels <= leaf_level: the
   !> stored sector ball, oriented box and cap-centre radius. Deeper levels: r0, the gradient g and
   !> the Hessian's largest |eigenvalue| h at the cap centre u0 (`radius_hessian`; x0 = r0 u0,
   !> normal n0 along r0 u0 - g). With alpha the cap's half-angle, T the certified bound of
   !> |d3r/ds3|, G = |g| + h alpha + T alpha^2/2 >= |dr/ds| and rhi >= r over the cap (Taylor
   !> along the great-circle arcs from u0), every surface point of the piece is within
   !> (rhi + G) alpha of x0 (arc length times the largest |dx/ds|) and within
   !> [((h + r0) r0 + 2 |g|^2) / |r0 u0 - g|] alpha^2/2 + (T + 3 (h + T alpha) + 3 G + rhi) alpha^3/6
   !> of the tangent plane at x0 (the first derivative of n0 . (x - x0) vanishes at x0; the
   !> second at x0 and the third along the arc are bounded so): a thin box about x0.
   pure subroutine w_node(x, f, is_a, l, i, j, plo, phi, other, nd, live)
      type(contact_body_type), intent(in) :: x
      type(w_frame_type), intent(in) :: f
      logical, intent(in) :: is_a
      integer, intent(in) :: l, i, j
      real(wp), intent(in) :: plo, phi
      type(w_node_type), intent(in) :: other
      type(w_node_type), intent(out) :: nd
      logical, intent(out) :: live
      real(wp) :: dir(3), cosa, sina, rlo, rhi, cen(3), rad, r0, rs, g(3), alpha, gl, w, lat, wn, nrm(3), t1(3), &
                  t2(3), th0, th1, ph0, ph1, be(3, 3), bh(3), hm, gn, hl, nn
      integer :: k
      ! the cap, its radial bounds and sector ball (stored down to leaf_level)
      if (l <= leaf_level) then
         k = patch_index(x, l, i, j)
         cen = x%ball(:, k)
         rad = x%brad(k)
      else
         if (l <= stored_level) then
            call patch_geometry(x, l, i, j, dir, cosa, sina)
            call patch_bounds(x, l, i, j, rlo, rhi)
            rlo = max(rlo, plo)
            rhi = min(rhi, phi)
         else
            call patch_rect(l, i, j, th0, th1, ph0, ph1)
            call patch_cap(th0, th1, ph0, ph1, dir, cosa, sina)
            rlo = plo
            rhi = phi
         end if
         call sector_ball(dir, cosa, sina, max(0.0_wp, rlo), rhi, cen, rad)
      end if
      call place_ball(f, is_a, cen, rad, other, nd, live)
      if (.not. live) return
      if (l <= leaf_level) then
         dir = x%dir(:, k)
         rlo = x%rlo(k)
         rhi = x%rhi(k)
         rs = x%node(nd_rc, k)
      else
         call x%shape%radius_hessian(dir, r0, g, hm)
         rs = r0
         alpha = atan2(sina, cosa)
         gn = norm2(g)
         ! Taylor bounds along the great-circle arcs from the cap centre (third derivative <= T)
         w = (gn * alpha + hm * alpha**2 * 0.5_wp + x%third * alpha**3 / 6.0_wp) * (1.0_wp + 1.0e-9_wp) &
             + 1.0e-12_wp * x%r_max
         rlo = max(rlo, r0 - w)
         rhi = min(rhi, r0 + w)
         hl = hm + x%third * alpha
         gl = (gn + hm * alpha + x%third * alpha**2 * 0.5_wp) * (1.0_wp + 1.0e-9_wp)
         lat = (rhi + gl) * alpha * (1.0_wp + 1.0e-9_wp)
         nn = norm2(r0 * dir - g)
         ! n0 . x(s) - n0 . x0: no first-order term; second derivative at the centre at most
         ! (hm + r0) r0 / |r0 u0 - g| + 2 |g|^2 / |r0 u0 - g|; third at most T + 3 H + 3 G + r
         wn = (((hm + r0) * r0 + 2.0_wp * gn**2) / nn * alpha**2 * 0.5_wp &
               + (x%third + 3.0_wp * hl + 3.0_wp * gl + rhi) * alpha**3 / 6.0_wp) * (1.0_wp + 1.0e-9_wp) &
              + 1.0e-12_wp * (lat + x%r_max)
         nrm = r0 * dir - g
         nrm = nrm / norm2(nrm)
         if (abs(nrm(1)) < 0.6_wp) then
            t1 = [0.0_wp, nrm(3), -nrm(2)]
         else
            t1 = [-nrm(3), 0.0_wp, nrm(1)]
         end if
         t1 = t1 / norm2(t1)
         t2 = [nrm(2) * t1(3) - nrm(3) * t1(2), nrm(3) * t1(1) - nrm(1) * t1(3), nrm(1) * t1(2) - nrm(2) * t1(1)]
         be(:, 1) = t1
         be(:, 2) = t2
         be(:, 3) = nrm
         bh = [lat, lat, wn]
         ! the thin box's ball about x0 replaces the sector ball
         call place_ball(f, is_a, r0 * dir, lat, other, nd, live)
         if (.not. live) return
      end if
      nd%l = l
      nd%i = i
      nd%j = j
      nd%rlo = rlo
      nd%rhi = rhi
      nd%sample = .true.
      if (is_a) then
         nd%p = matmul(f%pab%m, rs * dir) + f%pab%t
      else
         nd%p = rs * dir
      end if
      if (l > leaf_level) then
         if (is_a) then
            nd%bc = nd%c
            nd%be = matmul(f%rot, be)
            nd%bh = f%pab%k * bh
         else
            nd%bc = nd%c
            nd%be = be
            nd%bh = bh
         end if
         nd%br = nd%rho
      else if (is_a) then
         nd%bc = matmul(f%pab%m, x%node(nd_c:nd_c + 2, k)) + f%pab%t
         nd%be(:, 1) = matmul(f%rot, x%node(nd_e:nd_e + 2, k))
         nd%be(:, 2) = matmul(f%rot, x%node(nd_e + 3:nd_e + 5, k))
         nd%be(:, 3) = matmul(f%rot, x%node(nd_e + 6:nd_e + 8, k))
         nd%bh = f%pab%k * x%node(nd_h:nd_h + 2, k)
         nd%br = f%pab%k * x%node(nd_r, k) * (1.0_wp + 1.0e-12_wp)
      else
         nd%bc = x%node(nd_c:nd_c + 2, k)
         nd%be(:, 1) = x%node(nd_e:nd_e + 2, k)
         nd%be(:, 2) = x%node(nd_e + 3:nd_e + 5, k)
         nd%be(:, 3) = x%node(nd_e + 6:nd_e + 8, k)
         nd%bh = x%node(nd_h:nd_h + 2, k)
         nd%br = x%node(nd_r, k)
      end if
   end subroutine w_node

   !> A piece's ball (body-frame centre c0, radius r) into nd%c, nd%rho (B's frame) for `w_node`;
   !> live when it meets the body's world region in the frame `f` and comes within m of the ball of
   !> the other piece.
   pure subroutine place_ball(f, is_a, c0, r, other, nd, live)
      type(w_frame_type), intent(in) :: f
      logical, intent(in) :: is_a
      real(wp), intent(in) :: c0(3), r
      type(w_node_type), intent(in) :: other
      type(w_node_type), intent(inout) :: nd
      logical, intent(out) :: live
      if (is_a) then
         live = ball_in_box(f%pab%cw + matmul(f%pab%rw, c0), r * f%wsa * (1.0_wp + 1.0e-12_wp), f%alo, f%ahi)
         nd%c = matmul(f%pab%m, c0) + f%pab%t
         nd%rho = f%pab%k * r * (1.0_wp + 1.0e-12_wp)
      else
         live = ball_in_box(f%pba%cw + matmul(f%pba%rw, c0), r * f%wsb * (1.0_wp + 1.0e-12_wp), f%blo, f%bhi)
         nd%c = c0
         nd%rho = r
      end if
      if (live) live = sum((nd%c - other%c)**2) <= (nd%rho + other%rho + f%m)**2 * (1.0_wp + 1.0e-11_wp)
   end subroutine place_ball


   !> True when A's stored surface point of support-table cell c, moved towards A's centre by more
   !> than its rounding, lies inside B, or (margin m > 0, mm) closer than m to B's surface point
   !> on the ray from B's centre: then the bodies overlap (come closer than m).
   pure logical function reach_inside(a, ca, ra, sa, c, b, cb, rb, sb, m) result(inside)
      type(contact_body_type), intent(in) :: a, b
      real(wp), intent(in) :: ca(3), ra(3, 3), sa, cb(3), rb(3, 3), sb, m
      integer, intent(in) :: c
      real(wp) :: x(3), y(3), d, shrink
      ! the stored point is r(u) u to single precision (relative 6e-8, so its direction within
      ! 1e-7 rad, where r changes by at most lipschitz 1e-7): pulled in by more than that
      shrink = 1.0e-6_wp + 1.0e-6_wp * a%lipschitz / a%r_min
      x = real(a%supp(1:3, c), wp) * (1.0_wp - shrink)
      y = matmul(ca + sa * matmul(ra, x) - cb, rb) / sb
      d = norm2(y)
      if (d <= 0.0_wp) then
         inside = .true.
      else
         inside = d < b%shape%radius_dir(y / d) + m / sb
      end if
   end function reach_inside

   !> Thesis D_overlap (mm): the largest radial penetration, along rays to the other body's
   !> centre, of the surface points of either body on the N_box scan grid (theta_i =
   !> (i - 1/2) pi/N_box, phi_j = (j - 1/2) pi/N_box) that lie in the EOB, plus the two surface
   !> points on the line of centres; 0 when none penetrates. Patches certainly outside the other
   !> body are skipped (they contribute 0).
   pure function overlap_depth(body_a, center_a, rot_a, scale_a, body_b, center_b, rot_b, scale_b, nbox) &
      result(depth)
      !> First body.
      type(contact_body_type), intent(in) :: body_a
      !> Its centre (world, mm).
      real(wp), intent(in) :: center_a(3)
      !> Its rotation, body to world.
      real(wp), intent(in) :: rot_a(3, 3)
      !> Its scale (mm per shape unit).
      real(wp), intent(in) :: scale_a
      !> Second body.
      type(contact_body_type), intent(in) :: body_b
      !> Its centre.
      real(wp), intent(in) :: center_b(3)
      !> Its rotation.
      real(wp), intent(in) :: rot_b(3, 3)
      !> Its scale.
      real(wp), intent(in) :: scale_b
      !> Scan resolution N_box.
      integer, intent(in) :: nbox
      real(wp) :: depth
      real(wp) :: dvec(3), dist, eob_lo(3), eob_hi(3), u(3)
      type(pose_type) :: pab, pba
      integer :: i, j

      depth = 0.0_wp
      dvec = center_b - center_a
      dist = sqrt(sum(dvec**2))
      if (dist >= scale_a * body_a%r_max + scale_b * body_b%r_max) return
      call eob_box(body_a, center_a, rot_a, scale_a, body_b, center_b, rot_b, scale_b, .true., eob_lo, eob_hi)
      if (any(eob_lo > eob_hi)) return
      pab = make_pose(center_a, rot_a, scale_a, center_b, rot_b, scale_b)
      pba = make_pose(center_b, rot_b, scale_b, center_a, rot_a, scale_a)
      if (dist > 0.0_wp) then
         u = dvec / dist
         depth = max(depth, point_depth(body_a, body_b, pab, matmul(u, rot_a)))
         depth = max(depth, point_depth(body_b, body_a, pba, -matmul(u, rot_b)))
      end if
      do j = 1, patch_cols(0)
         do i = 1, patch_rows(0)
            call depth_patch(body_a, body_b, pab, eob_lo, eob_hi, max(1, nbox), 0, i, j, depth)
            call depth_patch(body_b, body_a, pba, eob_lo, eob_hi, max(1, nbox), 0, i, j, depth)
         end do
      end do
   end function overlap_depth

   !> True if any part of the posed body touches or leaves the box [0, L]^3, or with a margin m
   !> (mm) comes closer than m to a wall (the body is then tested against the box [m, L - m]^3).
   !> "False" is guaranteed by the certified patch bounds: patches still undecided at
   !> `wall_level` are reported as touching (a possible false positive within their bound width of
   !> the wall).
   pure logical function body_crosses_walls(body, center, rot, scale, box_length, margin) result(out)
      !> Body.
      type(contact_body_type), intent(in) :: body
      !> Centre (world, mm).
      real(wp), intent(in) :: center(3)
      !> Rotation, body to world.
      real(wp), intent(in) :: rot(3, 3)
      !> Scale (mm per shape unit).
      real(wp), intent(in) :: scale
      !> Box edge lengths (mm).
      real(wp), intent(in) :: box_length(3)
      !> Gap to keep from the walls (mm, default 0).
      real(wp), intent(in), optional :: margin
      real(wp) :: c(3), lb(3)
      c = center
      lb = box_length
      if (present(margin)) then
         if (margin > 0.0_wp) then
            c = center - margin
            lb = box_length - 2.0_wp * margin
         end if
      end if
      out = .true.
      if (any(lb <= 0.0_wp)) return
      out = crosses_box(body, c, rot, scale, lb)
   end function body_crosses_walls

   !> `body_crosses_walls` without a margin.
   pure logical function crosses_box(body, center, rot, scale, box_length) result(out)
      type(contact_body_type), intent(in) :: body
      real(wp), intent(in) :: center(3), rot(3, 3), scale, box_length(3)
      integer :: k, sgn, i, j, code
      real(wp) :: e(3), thr

      if (all(center - scale * body%r_max > 0.0_wp) .and. all(center + scale * body%r_max < box_length)) then
         out = .false.
         return
      end if
      out = .true.
      if (any(center - scale * body%r_min <= 0.0_wp) .or. any(center + scale * body%r_min >= box_length)) return
      do k = 1, 3
         do sgn = -1, 1, 2
            ! body-frame direction of the outward wall normal and the support threshold
            e = real(sgn, wp) * rot(k, :)
            if (sgn > 0) then
               thr = (box_length(k) - center(k)) / scale
            else
               thr = center(k) / scale
            end if
            if (body%r_max < thr) cycle
            code = code_none
            do j = 1, patch_cols(0)
               do i = 1, patch_rows(0)
                  call wall_patch(body, e, thr, 0, i, j, body%r_min, body%r_max, code)
                  if (code == code_inside) return
               end do
            end do
         end do
      end do
      out = .false.
   end function crosses_box

   !> True when the body-frame point p of body A (pose A->B) is inside body B.
   pure logical function point_inside(body_b, pose_m, pose_t, p) result(inside)
      !> Body B.
      type(contact_body_type), intent(in) :: body_b
      !> Linear part and offset of the A-body to B-body map.
      real(wp), intent(in) :: pose_m(3, 3), pose_t(3)
      !> Point in A's body frame.
      real(wp), intent(in) :: p(3)
      real(wp) :: y(3), d
      y = matmul(pose_m, p) + pose_t
      d = sqrt(sum(y**2))
      if (d <= 0.0_wp) then
         inside = .true.
      else
         inside = d < body_b%shape%radius_dir(y)
      end if
   end function point_inside

   ! ---------------------------------------------------------------------------------------------

   pure function make_pose(ca, ra, sa, cb, rb, sb) result(ps)
      real(wp), intent(in) :: ca(3), ra(3, 3), sa, cb(3), rb(3, 3), sb
      type(pose_type) :: ps
      ps%m = (sa / sb) * matmul(transpose(rb), ra)
      ps%t = matmul(ca - cb, rb) / sb
      ps%k = sa / sb
      ps%q = matmul(cb - ca, ra) / sa
      ps%rw = sa * ra
      ps%cw = ca
      ps%sb = sb
   end function make_pose

   pure subroutine world_box(lo, hi, c, rot, s, wlo, whi)
      real(wp), intent(in) :: lo(3), hi(3), c(3), rot(3, 3), s
      real(wp), intent(out) :: wlo(3), whi(3)
      real(wp) :: mid(3), half(3)
      mid = c + s * matmul(rot, 0.5_wp * (lo + hi))
      half = s * matmul(abs(rot), 0.5_wp * (hi - lo))
      wlo = mid - half
      whi = mid + half
   end subroutine world_box

   pure subroutine eob_box(a, ca, ra, sa, b, cb, rb, sb, certified, lo, hi)
      type(contact_body_type), intent(in) :: a, b
      real(wp), intent(in) :: ca(3), ra(3, 3), sa, cb(3), rb(3, 3), sb
      logical, intent(in) :: certified
      real(wp), intent(out) :: lo(3), hi(3)
      real(wp) :: alo(3), ahi(3), blo(3), bhi(3)
      if (certified) then
         call world_box(a%box_lo, a%box_hi, ca, ra, sa, alo, ahi)
         call world_box(b%box_lo, b%box_hi, cb, rb, sb, blo, bhi)
      else
         call world_box(a%ext_lo, a%ext_hi, ca, ra, sa, alo, ahi)
         call world_box(b%ext_lo, b%ext_hi, cb, rb, sb, blo, bhi)
      end if
      lo = max(alo, blo)
      hi = min(ahi, bhi)
   end subroutine eob_box

   pure logical function ball_in_box(x, rad, lo, hi) result(yes)
      real(wp), intent(in) :: x(3), rad, lo(3), hi(3)
      real(wp) :: q(3)
      q = max(lo - x, 0.0_wp, x - hi)
      yes = sum(q**2) <= rad**2
   end function ball_in_box

   !> Rectangle of patch (l, i, j).
   pure subroutine patch_rect(l, i, j, th0, th1, ph0, ph1)
      integer, intent(in) :: l, i, j
      real(wp), intent(out) :: th0, th1, ph0, ph1
      th0 = pi * (i - 1) / patch_rows(l)
      th1 = pi * i / patch_rows(l)
      ph0 = two_pi * (j - 1) / patch_cols(l)
      ph1 = two_pi * j / patch_cols(l)
   end subroutine patch_rect

   !> Cap, radial bounds and sector ball of patch (l, i, j): stored for l <= stored_level (caps
   !> of levels beyond leaf_level from the row/column tables), otherwise from r and |grad r| at the
   !> cap centre with `slope_bound` (r0 = r there, else r0 = -1); always intersected with the
   !> parent's bounds [plo, phi].
   pure subroutine patch_data(a, l, i, j, plo, phi, dir, cosa, sina, rlo, rhi, cen, rad, r0)
      type(contact_body_type), intent(in) :: a
      integer, intent(in) :: l, i, j
      real(wp), intent(in) :: plo, phi
      real(wp), intent(out) :: dir(3), cosa, sina, rlo, rhi, cen(3), rad, r0
      real(wp) :: th0, th1, ph0, ph1, g0, w
      integer :: k
      if (l <= leaf_level) then
         k = patch_index(a, l, i, j)
         dir = a%dir(:, k)
         cosa = a%cosa(k)
         sina = a%sina(k)
         rlo = a%rlo(k)
         rhi = a%rhi(k)
         cen = a%ball(:, k)
         rad = a%brad(k)
         r0 = -1.0_wp
         return
      end if
      if (l <= stored_level) then
         call patch_geometry(a, l, i, j, dir, cosa, sina)
         call patch_bounds(a, l, i, j, rlo, rhi)
         r0 = -1.0_wp
      else
         call patch_rect(l, i, j, th0, th1, ph0, ph1)
         call patch_cap(th0, th1, ph0, ph1, dir, cosa, sina)
         call a%shape%radius_slope(dir, r0, g0)
         w = slope_bound(a, g0, atan2(sina, cosa), sqrt(dir(1)**2 + dir(2)**2))
         rlo = r0 - w
         rhi = r0 + w
      end if
      rlo = max(rlo, plo)
      rhi = min(rhi, phi)
      call sector_ball(dir, cosa, sina, rlo, rhi, cen, rad)
   end subroutine patch_data

   !> Classify a shell sector of A against B: outside, inside or mixed. The sector lies in the
   !> ball of centre y (B's frame) and radius rho, and its distances to B's centre lie in
   !> [dmin, dmax] (`sector_range`, B units). Its points have directions within
   !> beta = asin(rho/|y|) of u = y/|y| and radii in [max(|y| - rho, dmin), min(|y| + rho, dmax)];
   !> it is outside (inside) when B's r over that cap is certainly below (above) that range. B's r
   !> is bounded by its stored patch bounds over the index rectangle that covers the cap
   !> (`cap_bounds`) and, when these do not decide and beta is small, by the local bound at u
   !> (`slope_bound`).
   pure function classify_ball(b, y, rho, dmin, dmax) result(code)
      type(contact_body_type), intent(in) :: b
      real(wp), intent(in) :: y(3), rho, dmin, dmax
      integer :: code
      real(wp), parameter :: beta_local = 0.02_wp
      real(wp) :: d, lo, hi, u(3), sinb, beta, r0, g0, w
      d = sqrt(sum(y**2))
      lo = max(d - rho, dmin)
      hi = min(d + rho, dmax)
      if (lo > b%r_max) then
         code = code_outside
         return
      end if
      if (hi < b%r_min) then
         code = code_inside
         return
      end if
      if (d <= rho) then
         code = code_mixed
         return
      end if
      u = y / d
      sinb = rho / d
      beta = asin(min(1.0_wp, sinb))
      code = cap_bounds(b, u, sinb, beta, lo, hi)
      if (code /= code_mixed .or. beta > beta_local) return
      if (u(1)**2 + u(2)**2 <= 1.0e-20_wp) return
      call b%shape%radius_slope(u, r0, g0)
      w = slope_bound(b, g0, beta, sqrt(u(1)**2 + u(2)**2))
      if (r0 + w < lo) then
         code = code_outside
      else if (r0 - w > hi) then
         code = code_inside
      end if
   end function classify_ball

   !> Range [smin, smax] of the distances from the point q to the shell sector
   !> {rho v : angle(v, dir) <= alpha, rlo <= rho <= rhi} (the exact extremes, rounded outwards).
   !> With gamma the angle from dir to q: when gamma <= alpha the nearest point is on the ray
   !> through q; otherwise it lies in the plane of dir and q on the cap's rim ray at angle
   !> delta = gamma - alpha from q, at rho = |q| cos delta clamped to [rlo, rhi]. The farthest
   !> point is on the rim ray at angle min(gamma + alpha, pi) from q, at rho = rlo or rhi (the
   !> squared distance is convex in rho). This does not pay the sector's tangential extent, unlike
   !> the bounding ball.
   pure subroutine sector_range(q, dir, cosa, sina, rlo, rhi, smin, smax)
      !> Point, unit cap direction, cos and sin of the cap half-angle alpha, radial range.
      real(wp), intent(in) :: q(3), dir(3), cosa, sina, rlo, rhi
      !> Lower and upper bound of |x - q| over the sector.
      real(wp), intent(out) :: smin, smax
      real(wp), parameter :: eps = 8.0_wp * epsilon(1.0_wp)
      real(wp) :: qn, cg, sg, cd, rho, lo, c(3), s2, scale2
      lo = max(0.0_wp, rlo)
      qn = sqrt(sum(q**2))
      if (qn <= 0.0_wp) then
         smin = lo
         smax = rhi
         return
      end if
      cg = dot_product(dir, q) / qn
      c = [dir(2) * q(3) - dir(3) * q(2), dir(3) * q(1) - dir(1) * q(3), dir(1) * q(2) - dir(2) * q(1)]
      sg = sqrt(sum(c**2)) / qn
      scale2 = eps * (qn + rhi)**2
      if (cg >= cosa) then
         ! (both branches agree at gamma = alpha; the shell distance bounds the distance anyway)
         smin = max(lo - qn, qn - rhi, 0.0_wp)
         smin = max(0.0_wp, smin - eps * (qn + rhi))
      else
         ! cos(gamma - alpha)
         cd = cg * cosa + sg * sina
         rho = max(lo, min(rhi, qn * cd))
         s2 = qn**2 + rho**2 - 2.0_wp * qn * rho * cd
         smin = sqrt(max(0.0_wp, s2 - scale2))
      end if
      ! cos(min(gamma + alpha, pi))
      if (sg * cosa + cg * sina >= 0.0_wp) then
         cd = cg * cosa - sg * sina
      else
         cd = -1.0_wp
      end if
      s2 = max(qn**2 + lo**2 - 2.0_wp * qn * lo * cd, qn**2 + rhi**2 - 2.0_wp * qn * rhi * cd)
      smax = sqrt(max(0.0_wp, s2 + scale2))
   end subroutine sector_range

   !> Stored bounds of B's r over the cap (u, beta) against the radial range [lo, hi]: the patches
   !> of one level whose index rectangle covers the polar range theta(u) +- beta and the azimuth
   !> range phi(u) +- asin(sin beta / sin theta(u)) (all azimuths when the cap holds a pole). The
   !> level is the finest stored one with patches of at least beta (coarser when near a pole the
   !> rectangle would be large); a mixed answer is retried once on the next finer level.
   !> `cap_outside`: r < lo over the whole cap; `cap_inside`: r > hi over it (certified patch bounds).
   pure function cap_bounds(b, u, sinb, beta, lo, hi) result(code)
      !> Body.
      type(contact_body_type), intent(in) :: b
      !> Cap axis (unit, body frame), sine of its half-angle and half-angle (rad).
      real(wp), intent(in) :: u(3), sinb, beta
      !> Radial range (shape units).
      real(wp), intent(in) :: lo, hi
      integer :: code
      integer, parameter :: max_count = 36
      real(wp), parameter :: eps = 1.0e-12_wp
      real(wp) :: th, ph, st, t0, t1, dph, rlo, rhi
      logical :: polar, all_out, all_in
      integer :: l, l0, i0, i1, j0, j1, i, j, jj, ncol, pass, nrow, ncl, k
      st = sqrt(u(1)**2 + u(2)**2)
      th = atan2(st, u(3))
      ph = atan2(u(2), u(1))
      if (ph < 0.0_wp) ph = ph + two_pi
      t0 = th - beta - eps
      t1 = th + beta + eps
      polar = t0 <= 0.0_wp .or. t1 >= pi
      dph = pi
      if (.not. polar) then
         if (sinb < st) dph = asin(sinb / st) + eps
      end if
      ! finest level whose patch size pi / (4 2^l) is at least beta
      if (beta > 0.0_wp) then
         l0 = max(0, min(stored_level, exponent(pi / (4.0_wp * beta)) - 1))
      else
         l0 = stored_level
      end if
      do l = l0, 0, -1
         call cover(l, i0, i1, j0, j1, ncol)
         if ((i1 - i0 + 1) * ncol <= max_count .or. l == 0) exit
      end do
      code = code_mixed
      do pass = 1, 2
         all_out = .true.
         all_in = .true.
         nrow = ishft(4, l)
         ncl = ishft(8, l)
         outer: do j = j0, j0 + ncol - 1
            jj = j
            if (jj < 1) jj = jj + ncl
            if (jj > ncl) jj = jj - ncl
            if (l <= leaf_level) then
               k = b%off(l) + (jj - 1) * nrow
               do i = i0, i1
                  if (b%rhi(k + i) >= lo) all_out = .false.
                  if (b%rlo(k + i) <= hi) all_in = .false.
                  if (.not. (all_out .or. all_in)) exit outer
               end do
            else
               k = b%doff(l) + (jj - 1) * nrow
               do i = i0, i1
                  rhi = real(b%dhi(k + i), wp)
                  rlo = real(b%dlo(k + i), wp)
                  if (rhi >= lo) all_out = .false.
                  if (rlo <= hi) all_in = .false.
                  if (.not. (all_out .or. all_in)) exit outer
               end do
            end if
         end do outer
         if (all_out) then
            code = code_outside
            return
         else if (all_in) then
            code = code_inside
            return
         end if
         if (l >= stored_level) return
         l = l + 1
         call cover(l, i0, i1, j0, j1, ncol)
         if ((i1 - i0 + 1) * ncol > 4 * max_count) return
      end do
   contains
      pure subroutine cover(lev, ia, ib, ja, jb, nc)
         integer, intent(in) :: lev
         integer, intent(out) :: ia, ib, ja, jb, nc
         real(wp) :: h
         h = pi / ishft(4, lev)
         ia = max(1, floor(t0 / h) + 1)
         ib = min(ishft(4, lev), floor(t1 / h) + 1)
         if (dph >= pi) then
            ja = 1
            jb = ishft(8, lev)
         else
            ja = floor((ph - dph) / h) + 1
            jb = floor((ph + dph) / h) + 1
         end if
         nc = min(jb - ja + 1, ishft(8, lev))
      end subroutine cover
   end function cap_bounds

   !> Radial gap (B units) of the A-frame point p to B's surface along the ray from B's centre:
   !> negative when p is inside B.
   pure function radial_gap(b, ps, p) result(g)
      type(contact_body_type), intent(in) :: b
      type(pose_type), intent(in) :: ps
      real(wp), intent(in) :: p(3)
      real(wp) :: g
      real(wp) :: y(3), d
      y = matmul(ps%m, p) + ps%t
      d = sqrt(sum(y**2))
      if (d <= 0.0_wp) then
         g = -b%r_min
      else
         g = d - b%shape%radius_dir(y)
      end if
   end function radial_gap

   !> Test A's surface against B. `found`: contact found (certified mode: within the gap
   !> tolerance). `certain` (when not found): every patch of A was proven outside B by certified
   !> tests (no N_box scan, no pruning by the thesis' N_ext box that the certified box `cbox` does
   !> not confirm), so A's surface is certainly outside B.
   pure subroutine probe_surface(a, b, ps, eob_lo, eob_hi, cbox_lo, cbox_hi, params, tol, found, certain)
      type(contact_body_type), intent(in) :: a, b
      type(pose_type), intent(in) :: ps
      real(wp), intent(in) :: eob_lo(3), eob_hi(3), cbox_lo(3), cbox_hi(3)
      type(contact_params_type), intent(in) :: params
      !> Certified mode: radial gap tolerance in B units.
      real(wp), intent(in) :: tol
      logical, intent(out) :: found, certain
      integer :: i, j, ls
      ls = stop_level(params)
      found = .false.
      certain = .true.
      do j = 1, patch_cols(0)
         do i = 1, patch_rows(0)
            call probe_patch(a, b, ps, eob_lo, eob_hi, cbox_lo, cbox_hi, params, tol, ls, 0, i, j, a%r_min, &
                             a%r_max, found, certain)
            if (found) return
         end do
      end do
   end subroutine probe_surface

   !> Finest level of `probe_patch`: stored_level (then N_box scan), in certified mode the level
   !> whose patches are within `resolution`.
   pure integer function stop_level(params) result(ls)
      type(contact_params_type), intent(in) :: params
      ls = stored_level
      if (params%certified) then
         do while (pi / patch_rows(ls) > params%resolution * (1.0_wp + 1.0e-12_wp) .and. ls < 24)
            ls = ls + 1
         end do
      end if
   end function stop_level

   !> Traverse the surface box hierarchies of A and B together (`body%obb_*`, certified). A pair
   !> of patches cannot hold a common surface point when the cone of B's patch directions misses
   !> the cone from B's centre that holds A's box (or vice versa), when their boxes are disjoint
   !> (containing balls, then the separating axis test), or when one of them lies outside the box
   !> [lo, hi] (the certified EOB: every common point of the bodies lies in it) or outside the
   !> other body's certified box. A's tree is descended depth first; each A patch carries the list
   !> of B patches its parent could not separate, B patches larger than it being replaced by their
   !> children. When a leaf patch of A is left with leaf patches of B, witnesses of contact are
   !> tested at once: the N_box scan points (in the EOB) of these leaf patches in default mode,
   !> their centre surface points (within the gap tolerance) in certified mode. After the
   !> traversal, if no witness was found, each such leaf patch of A is tested against B with
   !> `probe_patch`. `status`: sep_found when contact was found; sep_disjoint when every such leaf
   !> patch was found outside B by certified tests (then the surfaces do not meet); otherwise
   !> sep_unsure.
   pure subroutine separate_surfaces(a, b, pab, pba, pr, status)
      type(contact_body_type), intent(in) :: a, b
      type(pose_type), intent(in) :: pab, pba
      type(probe_type), intent(in) :: pr
      integer, intent(out) :: status
      integer :: nleaf, leaves(3, max_leaves), nbseen, bseen(max_leaves), n
      logical :: found, certain, live
      type(traversal_type) :: tr
      type(a_node_type) :: na
      type(b_node_type) :: list(patch_rows(0) * patch_cols(0))
      type(b_node_type) :: nb
      real(wp) :: bc(3), be(3, 3), bh(3), br
      integer :: ia, ja, ib, jb, nlist
      tr%rot = pab%m / pab%k
      tr%sa = sqrt(sum(pab%rw(:, 1)**2))
      tr%sb = sqrt(sum(pba%rw(:, 1)**2))
      tr%lo = pr%cbox_lo
      tr%hi = pr%cbox_hi
      status = sep_disjoint
      nleaf = 0
      nbseen = 0
      ! B's level-0 patches that meet the EOB and A's certified box (an oriented box in B's frame)
      bc = matmul(pab%m, 0.5_wp * (a%box_lo + a%box_hi)) + pab%t
      be = tr%rot
      bh = pab%k * 0.5_wp * (a%box_hi - a%box_lo)
      br = norm2(bh) * (1.0_wp + 1.0e-12_wp)
      nlist = 0
      do jb = 1, patch_cols(0)
         do ib = 1, patch_rows(0)
            call make_b_node(b%node, b%off, pba, tr, 0, ib, jb, nb, live)
            if (.not. live) cycle
            if (boxes_disjoint(b%node(nd_c:nd_c + 2, nb%k), b%node(nd_e:nd_e + 8, nb%k), b%node(nd_h:nd_h + 2, nb%k), &
                               b%node(nd_r, nb%k), bc, be, bh, br)) cycle
            nlist = nlist + 1
            list(nlist) = nb
         end do
      end do
      if (nlist == 0) return
      bc = 0.5_wp * (b%box_lo + b%box_hi)
      be = reshape([1.0_wp, 0.0_wp, 0.0_wp, 0.0_wp, 1.0_wp, 0.0_wp, 0.0_wp, 0.0_wp, 1.0_wp], [3, 3])
      bh = 0.5_wp * (b%box_hi - b%box_lo)
      br = norm2(bh) * (1.0_wp + 1.0e-12_wp)
      do ja = 1, patch_cols(0)
         do ia = 1, patch_rows(0)
            call make_a_node(a%node, a%off, pab, tr, 0, ia, ja, na, live)
            if (.not. live) cycle
            if (boxes_disjoint(na%c, na%e, na%h, na%r, bc, be, bh, br)) cycle
            call a_descend(a, b, pab, pba, tr, pr, na, list(1:nlist), status, nleaf, leaves, nbseen, bseen)
            if (status == sep_found) return
         end do
      end do
      if (status /= sep_disjoint) return
      ! no witness of contact: prove each leaf of A outside B (or find contact)
      do n = 1, nleaf
         found = .false.
         certain = .true.
         call probe_patch(a, b, pab, pr%eob_lo, pr%eob_hi, pr%cbox_lo, pr%cbox_hi, pr%params, pr%tol, &
                          pr%stop_level, leaf_level, leaves(2, n), leaves(3, n), a%r_min, a%r_max, found, certain)
         if (found) then
            status = sep_found
            return
         end if
         if (.not. certain) status = sep_unsure
      end do
   end subroutine separate_surfaces

   !> A's patch `na` against the B patches `parent` that its parent could not separate (see
   !> `separate_surfaces`).
   pure recursive subroutine a_descend(a, b, pab, pba, tr, pr, na, parent, status, nleaf, leaves, nbseen, bseen)
      type(contact_body_type), intent(in) :: a, b
      type(pose_type), intent(in) :: pab, pba
      type(traversal_type), intent(in) :: tr
      type(probe_type), intent(in) :: pr
      type(a_node_type), intent(in) :: na
      type(b_node_type), intent(in) :: parent(:)
      !> Traversal status; A's leaf patches met (storage index, row, column); B's leaf patches
      !> whose witness was tested (storage index).
      integer, intent(inout) :: status, nleaf, leaves(:, :), nbseen, bseen(:)
      integer, parameter :: max_list = 96
      type(b_node_type) :: list(max_list), work(max_list)
      type(a_node_type) :: nc
      integer :: n, nlist, nwork, di, dj, pass
      logical :: more, ok, found, live
      real(wp) :: th0, th1, ph0, ph1
      ! B patches not separated from A's patch; those larger than it are replaced by their children
      nlist = 0
      ok = .true.
      do n = 1, size(parent)
         if (patches_apart(a%node, b%node, na, parent(n))) cycle
         if (parent(n)%l < leaf_level .and. b%node(nd_r, parent(n)%k) > na%r) then
            call split_b(a%node, b%node, b%off, pba, tr, na, parent(n), list, nlist, ok)
         else if (nlist < max_list) then
            nlist = nlist + 1
            list(nlist) = parent(n)
         else
            ok = .false.
         end if
         if (.not. ok) then
            status = sep_unsure
            return
         end if
      end do
      if (nlist == 0) return
      if (na%l < leaf_level) then
         do dj = 0, 1
            do di = 0, 1
               call make_a_node(a%node, a%off, pab, tr, na%l + 1, 2 * na%i - 1 + di, 2 * na%j - 1 + dj, nc, live)
               if (.not. live) cycle
               call a_descend(a, b, pab, pba, tr, pr, nc, list(1:nlist), status, nleaf, leaves, nbseen, bseen)
               if (status == sep_found) return
            end do
         end do
         return
      end if
      ! leaf of A: refine B down to its leaves
      do pass = 1, leaf_level + 1
         more = .false.
         nwork = 0
         do n = 1, nlist
            if (list(n)%l < leaf_level) then
               more = .true.
               call split_b(a%node, b%node, b%off, pba, tr, na, list(n), work, nwork, ok)
               if (.not. ok) then
                  status = sep_unsure
                  return
               end if
            else if (nwork < max_list) then
               nwork = nwork + 1
               work(nwork) = list(n)
            else
               ! list overflow (was an out-of-bounds write): stage 4b decides
               status = sep_unsure
               return
            end if
         end do
         nlist = nwork
         list(1:nlist) = work(1:nwork)
         if (nlist == 0) return
         if (.not. more) exit
      end do
      ! A's leaf patch may meet B's surface: remember it (once)
      do n = 1, nleaf
         if (leaves(1, n) == na%k) return
      end do
      if (nleaf >= size(leaves, 2)) then
         status = sep_unsure
         return
      end if
      nleaf = nleaf + 1
      leaves(:, nleaf) = [na%k, na%i, na%j]
      if (pr%params%certified) then
         ! witnesses of contact first (the proofs wait until every leaf is known): the centre
         ! surface points of A's leaf and of the B leaves, tested along the ray from the other
         ! centre
         if (radial_gap(b, pab, a%node(nd_rc, na%k) * a%node(nd_dir:nd_dir + 2, na%k)) <= pr%tol) then
            status = sep_found
            return
         end if
         do n = 1, nlist
            if (any(bseen(1:min(nbseen, size(bseen))) == list(n)%k)) cycle
            nbseen = nbseen + 1
            if (nbseen <= size(bseen)) bseen(nbseen) = list(n)%k
            if (radial_gap(a, pba, b%node(nd_rc, list(n)%k) * b%node(nd_dir:nd_dir + 2, list(n)%k)) <= pr%tol_a) then
               status = sep_found
               return
            end if
         end do
      else
         ! default mode: the N_box scan points of A's leaf and of the B leaves
         call patch_rect(leaf_level, na%i, na%j, th0, th1, ph0, ph1)
         found = .false.
         call scan_rect(a, b, pab, pr%eob_lo, pr%eob_hi, pr%params%nbox, th0, th1, ph0, ph1, found)
         if (found) then
            status = sep_found
            return
         end if
         do n = 1, nlist
            if (any(bseen(1:min(nbseen, size(bseen))) == list(n)%k)) cycle
            nbseen = nbseen + 1
            if (nbseen <= size(bseen)) bseen(nbseen) = list(n)%k
            call patch_rect(leaf_level, list(n)%i, list(n)%j, th0, th1, ph0, ph1)
            call scan_rect(b, a, pba, pr%eob_lo, pr%eob_hi, pr%params%nbox, th0, th1, ph0, ph1, found)
            if (found) then
               status = sep_found
               return
            end if
         end do
      end if
   end subroutine a_descend

   !> Append the children of B's patch y that are not separated from A's patch na to out(1:nout)
   !> (`ok` false when out is full). pa, pb: the bodies' `node` arrays; offb: B's level offsets.
   pure subroutine split_b(pa, pb, offb, pba, tr, na, y, out, nout, ok)
      real(wp), intent(in) :: pa(node_size, *), pb(node_size, *)
      integer, intent(in) :: offb(0:)
      type(pose_type), intent(in) :: pba
      type(traversal_type), intent(in) :: tr
      type(a_node_type), intent(in) :: na
      type(b_node_type), intent(in) :: y
      type(b_node_type), intent(inout) :: out(:)
      integer, intent(inout) :: nout
      logical, intent(inout) :: ok
      type(b_node_type) :: yc
      integer :: ei, ej, k, l, i, j
      real(wp) :: dx, dy, dz
      logical :: live
      l = y%l + 1
      do ej = 0, 1
         do ei = 0, 1
            i = 2 * y%i - 1 + ei
            j = 2 * y%j - 1 + ej
            k = offb(l) + (j - 1) * ishft(4, l) + i
            ! cheap tests on stored data first: cone of A's box against the patch cap, balls
            if (na%cone) then
               if (cones_apart(na%u, na%sinb, na%cosb, pb(nd_dir:nd_dir + 2, k), pb(nd_cosa, k), pb(nd_sina, k))) cycle
            end if
            dx = pb(nd_c, k) - na%c(1)
            dy = pb(nd_c + 1, k) - na%c(2)
            dz = pb(nd_c + 2, k) - na%c(3)
            if (dx * dx + dy * dy + dz * dz > (na%r + pb(nd_r, k))**2 * (1.0_wp + 1.0e-11_wp)) cycle
            call make_b_node(pb, offb, pba, tr, l, i, j, yc, live)
            if (.not. live) cycle
            if (yc%cone) then
               if (cones_apart(yc%u, yc%sinb, yc%cosb, pa(nd_dir:nd_dir + 2, na%k), pa(nd_cosa, na%k), &
                               pa(nd_sina, na%k))) cycle
            end if
            if (boxes_disjoint(na%c, na%e, na%h, na%r, pb(nd_c:nd_c + 2, k), pb(nd_e:nd_e + 8, k), pb(nd_h:nd_h + 2, k), &
                               pb(nd_r, k))) cycle
            if (nout >= size(out)) then
               ok = .false.
               return
            end if
            nout = nout + 1
            out(nout) = yc
         end do
      end do
   end subroutine split_b

   !> A's patch (l, i, j): its box in B's frame and its cone from B's centre; `live` false when
   !> its sector ball misses the EOB. pa: A's `node` array; offa: its level offsets.
   pure subroutine make_a_node(pa, offa, pab, tr, l, i, j, nd, live)
      real(wp), intent(in) :: pa(node_size, *)
      integer, intent(in) :: offa(0:)
      type(pose_type), intent(in) :: pab
      type(traversal_type), intent(in) :: tr
      integer, intent(in) :: l, i, j
      type(a_node_type), intent(out) :: nd
      logical, intent(out) :: live
      integer :: k, m
      real(wp) :: x1, x2, x3
      k = offa(l) + (j - 1) * ishft(4, l) + i
      nd%l = l
      nd%i = i
      nd%j = j
      nd%k = k
      x1 = pa(nd_ball, k)
      x2 = pa(nd_ball + 1, k)
      x3 = pa(nd_ball + 2, k)
      live = ball_in_box(pab%cw + pab%rw(:, 1) * x1 + pab%rw(:, 2) * x2 + pab%rw(:, 3) * x3, pa(nd_brad, k) * tr%sa, &
                         tr%lo, tr%hi)
      if (.not. live) return
      x1 = pa(nd_c, k)
      x2 = pa(nd_c + 1, k)
      x3 = pa(nd_c + 2, k)
      nd%c = pab%m(:, 1) * x1 + pab%m(:, 2) * x2 + pab%m(:, 3) * x3 + pab%t
      do m = 0, 2
         x1 = pa(nd_e + 3 * m, k)
         x2 = pa(nd_e + 3 * m + 1, k)
         x3 = pa(nd_e + 3 * m + 2, k)
         nd%e(:, m + 1) = tr%rot(:, 1) * x1 + tr%rot(:, 2) * x2 + tr%rot(:, 3) * x3
      end do
      nd%h = pab%k * pa(nd_h:nd_h + 2, k)
      nd%r = pab%k * pa(nd_r, k) * (1.0_wp + 1.0e-12_wp)
      call ball_cone(nd%c, nd%r, nd%u, nd%sinb, nd%cosb, nd%cone)
   end subroutine make_a_node

   !> B's patch (l, i, j): its cone from A's centre (A's frame); `live` false when its sector
   !> ball misses the EOB. pb: B's `node` array; offb: its level offsets.
   pure subroutine make_b_node(pb, offb, pba, tr, l, i, j, nd, live)
      real(wp), intent(in) :: pb(node_size, *)
      integer, intent(in) :: offb(0:)
      type(pose_type), intent(in) :: pba
      type(traversal_type), intent(in) :: tr
      integer, intent(in) :: l, i, j
      type(b_node_type), intent(out) :: nd
      logical, intent(out) :: live
      integer :: k
      real(wp) :: c(3), x1, x2, x3
      k = offb(l) + (j - 1) * ishft(4, l) + i
      nd%l = l
      nd%i = i
      nd%j = j
      nd%k = k
      x1 = pb(nd_ball, k)
      x2 = pb(nd_ball + 1, k)
      x3 = pb(nd_ball + 2, k)
      live = ball_in_box(pba%cw + pba%rw(:, 1) * x1 + pba%rw(:, 2) * x2 + pba%rw(:, 3) * x3, pb(nd_brad, k) * tr%sb, &
                         tr%lo, tr%hi)
      if (.not. live) return
      x1 = pb(nd_c, k)
      x2 = pb(nd_c + 1, k)
      x3 = pb(nd_c + 2, k)
      c = pba%m(:, 1) * x1 + pba%m(:, 2) * x2 + pba%m(:, 3) * x3 + pba%t
      call ball_cone(c, pba%k * pb(nd_r, k) * (1.0_wp + 1.0e-12_wp), nd%u, nd%sinb, nd%cosb, nd%cone)
   end subroutine make_b_node

   !> Cone from the origin holding the ball (c, r): axis u, sin and cos of the half-angle
   !> (`cone` false when the ball holds the origin).
   pure subroutine ball_cone(c, r, u, sinb, cosb, cone)
      real(wp), intent(in) :: c(3), r
      real(wp), intent(out) :: u(3), sinb, cosb
      logical, intent(out) :: cone
      real(wp) :: d
      d = sqrt(c(1)**2 + c(2)**2 + c(3)**2)
      cone = d > r * (1.0_wp + 1.0e-12_wp)
      if (.not. cone) then
         u = 0.0_wp
         sinb = 1.0_wp
         cosb = 0.0_wp
         return
      end if
      u = c / d
      sinb = r / d
      cosb = sqrt(max(0.0_wp, 1.0_wp - sinb**2))
   end subroutine ball_cone

   !> True when A's patch na and B's patch y are separated: cones, containing balls, boxes.
   pure logical function patches_apart(pa, pb, na, y) result(apart)
      real(wp), intent(in) :: pa(node_size, *), pb(node_size, *)
      type(a_node_type), intent(in) :: na
      type(b_node_type), intent(in) :: y
      integer :: k
      apart = .true.
      k = y%k
      if (na%cone) then
         if (cones_apart(na%u, na%sinb, na%cosb, pb(nd_dir:nd_dir + 2, k), pb(nd_cosa, k), pb(nd_sina, k))) return
      end if
      if (y%cone) then
         if (cones_apart(y%u, y%sinb, y%cosb, pa(nd_dir:nd_dir + 2, na%k), pa(nd_cosa, na%k), pa(nd_sina, na%k))) return
      end if
      apart = boxes_disjoint(na%c, na%e, na%h, na%r, pb(nd_c:nd_c + 2, k), pb(nd_e:nd_e + 8, k), pb(nd_h:nd_h + 2, k), &
                             pb(nd_r, k))
   end function patches_apart

   !> True when the cone (u, sinb, cosb) (half-angle beta <= pi/2) misses the cap (dir, cosa,
   !> sina) (half-angle alpha <= pi/2): the angle between the axes exceeds alpha + beta, i.e.
   !> u . dir < cos(alpha + beta) (with a margin).
   pure logical function cones_apart(u, sinb, cosb, dir, cosa, sina) result(apart)
      real(wp), intent(in) :: u(3), sinb, cosb, dir(3), cosa, sina
      apart = cosa >= 0.0_wp .and. &
              u(1) * dir(1) + u(2) * dir(2) + u(3) * dir(3) < cosa * cosb - sina * sinb - 1.0e-12_wp
   end function cones_apart

   !> Separating axis test of two oriented boxes (centre, orthonormal axes as columns,
   !> half-extents, radius of a containing ball): true when their balls are apart or one of the
   !> 15 axes (6 face normals, 9 edge cross products) separates them, with a relative margin so
   !> that "disjoint" holds despite rounding. The normals (the thin directions) come first.
   pure logical function boxes_disjoint(c1, e1, h1, r1, c2, e2, h2, r2) result(sep)
      real(wp), intent(in) :: c1(3), e1(3, 3), h1(3), r1, c2(3), e2(3, 3), h2(3), r2
      real(wp), parameter :: eps = 1.0e-12_wp
      real(wp) :: dx, dy, dz, dd, tol, t1, t2, t3, s1, s2, s3
      real(wp) :: r11, r12, r13, r21, r22, r23, r31, r32, r33
      real(wp) :: a11, a12, a13, a21, a22, a23, a31, a32, a33
      sep = .true.
      dx = c2(1) - c1(1)
      dy = c2(2) - c1(2)
      dz = c2(3) - c1(3)
      dd = dx * dx + dy * dy + dz * dz
      if (dd > (r1 + r2)**2 * (1.0_wp + 4.0_wp * eps)) return
      tol = eps * (r1 + r2 + sqrt(dd))
      ! normal of box 2: r_i3 = e1_i . e2_3
      r13 = e1(1, 1) * e2(1, 3) + e1(2, 1) * e2(2, 3) + e1(3, 1) * e2(3, 3)
      r23 = e1(1, 2) * e2(1, 3) + e1(2, 2) * e2(2, 3) + e1(3, 2) * e2(3, 3)
      r33 = e1(1, 3) * e2(1, 3) + e1(2, 3) * e2(2, 3) + e1(3, 3) * e2(3, 3)
      s3 = dx * e2(1, 3) + dy * e2(2, 3) + dz * e2(3, 3)
      if (abs(s3) > h2(3) + h1(1) * abs(r13) + h1(2) * abs(r23) + h1(3) * abs(r33) + tol) return
      ! normal of box 1
      r31 = e1(1, 3) * e2(1, 1) + e1(2, 3) * e2(2, 1) + e1(3, 3) * e2(3, 1)
      r32 = e1(1, 3) * e2(1, 2) + e1(2, 3) * e2(2, 2) + e1(3, 3) * e2(3, 2)
      t3 = dx * e1(1, 3) + dy * e1(2, 3) + dz * e1(3, 3)
      a31 = abs(r31) + eps
      a32 = abs(r32) + eps
      a33 = abs(r33) + eps
      if (abs(t3) > h1(3) + h2(1) * a31 + h2(2) * a32 + h2(3) * a33 + tol) return
      ! the other faces
      r11 = e1(1, 1) * e2(1, 1) + e1(2, 1) * e2(2, 1) + e1(3, 1) * e2(3, 1)
      r12 = e1(1, 1) * e2(1, 2) + e1(2, 1) * e2(2, 2) + e1(3, 1) * e2(3, 2)
      r21 = e1(1, 2) * e2(1, 1) + e1(2, 2) * e2(2, 1) + e1(3, 2) * e2(3, 1)
      r22 = e1(1, 2) * e2(1, 2) + e1(2, 2) * e2(2, 2) + e1(3, 2) * e2(3, 2)
      a11 = abs(r11) + eps
      a12 = abs(r12) + eps
      a13 = abs(r13) + eps
      a21 = abs(r21) + eps
      a22 = abs(r22) + eps
      a23 = abs(r23) + eps
      t1 = dx * e1(1, 1) + dy * e1(2, 1) + dz * e1(3, 1)
      t2 = dx * e1(1, 2) + dy * e1(2, 2) + dz * e1(3, 2)
      if (abs(t1) > h1(1) + h2(1) * a11 + h2(2) * a12 + h2(3) * a13 + tol) return
      if (abs(t2) > h1(2) + h2(1) * a21 + h2(2) * a22 + h2(3) * a23 + tol) return
      s1 = t1 * r11 + t2 * r21 + t3 * r31
      s2 = t1 * r12 + t2 * r22 + t3 * r32
      if (abs(s1) > h2(1) + h1(1) * a11 + h1(2) * a21 + h1(3) * a31 + tol) return
      if (abs(s2) > h2(2) + h1(1) * a12 + h1(2) * a22 + h1(3) * a32 + tol) return
      ! edge-edge axes e1_i x e2_j: |t_i2 r_i1j - t_i1 r_i2j| > h1_i1 a_i2j + h1_i2 a_i1j
      ! + h2_j1 a_ij2 + h2_j2 a_ij1, (i, i1, i2) and (j, j1, j2) cyclic
      if (abs(t3 * r21 - t2 * r31) > h1(2) * a31 + h1(3) * a21 + h2(2) * a13 + h2(3) * a12 + tol) return
      if (abs(t3 * r22 - t2 * r32) > h1(2) * a32 + h1(3) * a22 + h2(3) * a11 + h2(1) * a13 + tol) return
      if (abs(t3 * r23 - t2 * r33) > h1(2) * a33 + h1(3) * a23 + h2(1) * a12 + h2(2) * a11 + tol) return
      if (abs(t1 * r31 - t3 * r11) > h1(3) * a11 + h1(1) * a31 + h2(2) * a23 + h2(3) * a22 + tol) return
      if (abs(t1 * r32 - t3 * r12) > h1(3) * a12 + h1(1) * a32 + h2(3) * a21 + h2(1) * a23 + tol) return
      if (abs(t1 * r33 - t3 * r13) > h1(3) * a13 + h1(1) * a33 + h2(1) * a22 + h2(2) * a21 + tol) return
      if (abs(t2 * r11 - t1 * r21) > h1(1) * a21 + h1(2) * a11 + h2(2) * a33 + h2(3) * a32 + tol) return
      if (abs(t2 * r12 - t1 * r22) > h1(1) * a22 + h1(2) * a12 + h2(3) * a31 + h2(1) * a33 + tol) return
      if (abs(t2 * r13 - t1 * r23) > h1(1) * a23 + h1(2) * a13 + h2(1) * a32 + h2(2) * a31 + tol) return
      sep = .false.
   end function boxes_disjoint

   pure recursive subroutine probe_patch(a, b, ps, eob_lo, eob_hi, cbox_lo, cbox_hi, params, tol, stop_level, l, &
                                         i, j, plo, phi, found, certain)
      type(contact_body_type), intent(in) :: a, b
      type(pose_type), intent(in) :: ps
      real(wp), intent(in) :: eob_lo(3), eob_hi(3), cbox_lo(3), cbox_hi(3), tol
      type(contact_params_type), intent(in) :: params
      integer, intent(in) :: stop_level, l, i, j
      real(wp), intent(in) :: plo, phi
      logical, intent(inout) :: found, certain
      real(wp) :: dir(3), cosa, sina, rlo, rhi, cen(3), rad, r0, th0, th1, ph0, ph1, smin, smax, xw(3), rw
      integer :: code, di, dj

      call patch_data(a, l, i, j, plo, phi, dir, cosa, sina, rlo, rhi, cen, rad, r0)
      xw = ps%cw + matmul(ps%rw, cen)
      rw = rad * sqrt(sum(ps%rw(:, 1)**2))
      if (.not. ball_in_box(xw, rw, eob_lo, eob_hi)) then
         if (certain) certain = .not. ball_in_box(xw, rw, cbox_lo, cbox_hi)
         return
      end if
      call sector_range(ps%q, dir, cosa, sina, rlo, rhi, smin, smax)
      code = classify_ball(b, matmul(ps%m, cen) + ps%t, ps%k * rad, ps%k * smin, ps%k * smax)
      if (code == code_outside) return
      if (code == code_inside) then
         found = .true.
         return
      end if
      if (r0 > 0.0_wp) then
         ! on-the-fly patch (certified mode): its centre surface point decides contact when it is
         ! inside B or within the gap tolerance of B's surface
         if (radial_gap(b, ps, r0 * dir) <= tol) then
            found = .true.
            return
         end if
      end if
      if (l >= stop_level) then
         if (params%certified) then
            found = .true.
         else
            ! undecided at the finest stored level: scan at N_box
            certain = .false.
            call patch_rect(l, i, j, th0, th1, ph0, ph1)
            call scan_rect(a, b, ps, eob_lo, eob_hi, params%nbox, th0, th1, ph0, ph1, found)
         end if
         return
      end if
      do dj = 0, 1
         do di = 0, 1
            call probe_patch(a, b, ps, eob_lo, eob_hi, cbox_lo, cbox_hi, params, tol, stop_level, l + 1, &
                             2 * i - 1 + di, 2 * j - 1 + dj, rlo, rhi, found, certain)
            if (found) return
         end do
      end do
   end subroutine probe_patch

   !> Index range of the N_box scan angles (k - 1/2) pi/nbox inside [x0, x1).
   pure subroutine grid_range(x0, x1, nbox, k0, k1)
      real(wp), intent(in) :: x0, x1
      integer, intent(in) :: nbox
      integer, intent(out) :: k0, k1
      k0 = ceiling(x0 * nbox / pi + 0.5_wp)
      k1 = ceiling(x1 * nbox / pi + 0.5_wp) - 1
   end subroutine grid_range

   pure subroutine scan_rect(a, b, ps, eob_lo, eob_hi, nbox, th0, th1, ph0, ph1, found)
      type(contact_body_type), intent(in) :: a, b
      type(pose_type), intent(in) :: ps
      real(wp), intent(in) :: eob_lo(3), eob_hi(3), th0, th1, ph0, ph1
      integer, intent(in) :: nbox
      logical, intent(inout) :: found
      integer :: i0, i1, j0, j1, i, j
      real(wp) :: th, ph, u(3), p(3), x(3)
      call grid_range(th0, th1, nbox, i0, i1)
      call grid_range(ph0, ph1, nbox, j0, j1)
      do j = j0, j1
         ph = pi * (j - 0.5_wp) / nbox
         do i = i0, i1
            th = pi * (i - 0.5_wp) / nbox
            u = [sin(th) * cos(ph), sin(th) * sin(ph), cos(th)]
            p = a%shape%radius_dir(u) * u
            x = ps%cw + matmul(ps%rw, p)
            if (any(x < eob_lo) .or. any(x > eob_hi)) cycle
            if (point_inside(b, ps%m, ps%t, p)) then
               found = .true.
               return
            end if
         end do
      end do
   end subroutine scan_rect

   !> Radial penetration (mm) of A's surface point in direction u (A body frame) into B.
   pure function point_depth(a, b, ps, u) result(depth)
      type(contact_body_type), intent(in) :: a, b
      type(pose_type), intent(in) :: ps
      real(wp), intent(in) :: u(3)
      real(wp) :: depth
      real(wp) :: p(3), y(3), d
      p = a%shape%radius_dir(u) * u / sqrt(sum(u**2))
      y = matmul(ps%m, p) + ps%t
      d = sqrt(sum(y**2))
      if (d <= 0.0_wp) then
         depth = b%r_min * ps%sb
      else
         depth = max(0.0_wp, (b%shape%radius_dir(y) - d) * ps%sb)
      end if
   end function point_depth

   pure recursive subroutine depth_patch(a, b, ps, eob_lo, eob_hi, nbox, l, i, j, depth)
      type(contact_body_type), intent(in) :: a, b
      type(pose_type), intent(in) :: ps
      real(wp), intent(in) :: eob_lo(3), eob_hi(3)
      integer, intent(in) :: nbox, l, i, j
      real(wp), intent(inout) :: depth
      integer :: k, di, dj, i0, i1, j0, j1, ii, jj
      real(wp) :: th0, th1, ph0, ph1, th, ph, u(3), x(3), smin, smax
      k = patch_index(a, l, i, j)
      if (.not. ball_in_box(ps%cw + matmul(ps%rw, a%ball(:, k)), a%brad(k) * sqrt(sum(ps%rw(:, 1)**2)), &
                            eob_lo, eob_hi)) return
      call sector_range(ps%q, a%dir(:, k), a%cosa(k), a%sina(k), a%rlo(k), a%rhi(k), smin, smax)
      if (classify_ball(b, matmul(ps%m, a%ball(:, k)) + ps%t, ps%k * a%brad(k), ps%k * smin, ps%k * smax) &
          == code_outside) return
      if (l < leaf_level) then
         do dj = 0, 1
            do di = 0, 1
               call depth_patch(a, b, ps, eob_lo, eob_hi, nbox, l + 1, 2 * i - 1 + di, 2 * j - 1 + dj, depth)
            end do
         end do
         return
      end if
      call patch_rect(l, i, j, th0, th1, ph0, ph1)
      call grid_range(th0, th1, nbox, i0, i1)
      call grid_range(ph0, ph1, nbox, j0, j1)
      do jj = j0, j1
         ph = pi * (jj - 0.5_wp) / nbox
         do ii = i0, i1
            th = pi * (ii - 0.5_wp) / nbox
            u = [sin(th) * cos(ph), sin(th) * sin(ph), cos(th)]
            x = ps%cw + matmul(ps%rw, a%shape%radius_dir(u) * u)
            if (any(x < eob_lo) .or. any(x > eob_hi)) cycle
            depth = max(depth, point_depth(a, b, ps, u))
         end do
      end do
   end subroutine depth_patch

   !> Support test against a wall: code_inside when some body point may have y.e >= thr. Patches
   !> are refined down to `wall_level` (stored bounds, then local bounds); a patch still undecided
   !> there is reported as touching.
   pure recursive subroutine wall_patch(a, e, thr, l, i, j, plo, phi, code)
      type(contact_body_type), intent(in) :: a
      real(wp), intent(in) :: e(3), thr, plo, phi
      integer, intent(in) :: l, i, j
      integer, intent(inout) :: code
      real(wp) :: dir(3), cosa, sina, rlo, rhi, cen(3), rad, r0, ang, mu, ub
      integer :: di, dj
      call patch_data(a, l, i, j, plo, phi, dir, cosa, sina, rlo, rhi, cen, rad, r0)
      if (r0 > 0.0_wp) then
         if (r0 * dot_product(dir, e) >= thr) then
            code = code_inside
            return
         end if
      end if
      if (rlo * dot_product(dir, e) >= thr) then
         code = code_inside
         return
      end if
      ang = acos(max(-1.0_wp, min(1.0_wp, dot_product(dir, e)))) - atan2(sina, cosa)
      mu = cos(max(0.0_wp, ang))
      if (mu >= 0.0_wp) then
         ub = rhi * mu
      else
         ub = max(0.0_wp, rlo) * mu
      end if
      ub = min(ub, dot_product(cen, e) + rad)
      if (ub < thr) return
      if (l >= wall_level) then
         code = code_inside
         return
      end if
      do dj = 0, 1
         do di = 0, 1
            call wall_patch(a, e, thr, l + 1, 2 * i - 1 + di, 2 * j - 1 + dj, rlo, rhi, code)
            if (code == code_inside) return
         end do
      end do
   end subroutine wall_patch

   !> Legacy Newton-Raphson contact (Eq 1.5 with theta_2, phi_2 eliminated along the ray to B's centre).
   pure logical function nr_overlap(a, ca, ra, sa, b, cb, rb, sb, params) result(hit)
      type(contact_body_type), intent(in) :: a, b
      real(wp), intent(in) :: ca(3), ra(3, 3), sa, cb(3), rb(3, 3), sb
      type(contact_params_type), intent(in) :: params
      type(pose_type) :: pab, pba
      integer :: il, is, it
      real(wp) :: ph, th, g, gp, gm, step, tol
      real(wp), parameter :: h = 1.0e-7_wp

      pab = make_pose(ca, ra, sa, cb, rb, sb)
      pba = make_pose(cb, rb, sb, ca, ra, sa)
      hit = .true.
      if (point_inside(b, pab%m, pab%t, [0.0_wp, 0.0_wp, 0.0_wp])) return
      if (point_inside(a, pba%m, pba%t, [0.0_wp, 0.0_wp, 0.0_wp])) return
      tol = 1.0e-10_wp * b%r_max
      do il = 0, params%nr_lines - 1
         ph = two_pi * il / max(1, params%nr_lines)
         do is = 1, params%nr_starts
            th = pi * (is - 0.5_wp) / params%nr_starts
            do it = 1, params%nr_iterations
               g = gap(th)
               if (abs(g) <= tol) return
               gp = gap(th + h)
               gm = gap(th - h)
               if (gp == gm) exit
               step = g * 2.0_wp * h / (gp - gm)
               th = th - step
               if (th < -0.1_wp .or. th > pi + 0.1_wp) exit
            end do
         end do
      end do
      hit = .false.
   contains
      pure function gap(t) result(gv)
         real(wp), intent(in) :: t
         real(wp) :: gv
         real(wp) :: u(3), y(3), d
         u = [sin(t) * cos(ph), sin(t) * sin(ph), cos(t)]
         y = matmul(pab%m, a%shape%radius_dir(u) * u) + pab%t
         d = sqrt(sum(y**2))
         gv = d - b%shape%radius_dir(y)
      end function gap
   end function nr_overlap
end module anm_contact_overlap
